"""Unit strings of the project → FMI unit definitions (SI base-unit exponents and a factor).

The project writes units as products with ``.``, powers as trailing integers and at most one
``/``: ``"m"``, ``"rad/s"``, ``"N.m.s/rad"``, ``"kg.m2"``, ``"N/m"``, ``"bar"``, ``"1"``.
A unit definition in FMI expresses a unit as ``factor * kg^a m^b s^c A^d K^e mol^f cd^g rad^h``
(FMI 2.0 §2.2.2, FMI 3.0 §2.4.3), e.g. ``bar = 1e5 kg m^-1 s^-2``.
"""
from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass

#: The base units of FMI unit definitions, in the order the standard lists them.
BASE_UNITS: tuple[str, ...] = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

_NEWTON = {"kg": 1, "m": 1, "s": -2}
_PASCAL = {"kg": 1, "m": -1, "s": -2}
_JOULE = {"kg": 1, "m": 2, "s": -2}

#: Known unit symbols: factor to SI and base-unit exponents.
SYMBOLS: dict[str, tuple[float, dict[str, int]]] = {
    "1": (1.0, {}),
    "m": (1.0, {"m": 1}),
    "mm": (1e-3, {"m": 1}),
    "cm": (1e-2, {"m": 1}),
    "km": (1e3, {"m": 1}),
    "kg": (1.0, {"kg": 1}),
    "g": (1e-3, {"kg": 1}),
    "t": (1e3, {"kg": 1}),
    "s": (1.0, {"s": 1}),
    "ms": (1e-3, {"s": 1}),
    "min": (60.0, {"s": 1}),
    "h": (3600.0, {"s": 1}),
    "A": (1.0, {"A": 1}),
    "K": (1.0, {"K": 1}),
    "mol": (1.0, {"mol": 1}),
    "cd": (1.0, {"cd": 1}),
    "rad": (1.0, {"rad": 1}),
    "deg": (math.pi / 180.0, {"rad": 1}),
    "rpm": (2.0 * math.pi / 60.0, {"rad": 1, "s": -1}),
    "Hz": (1.0, {"s": -1}),
    "N": (1.0, _NEWTON),
    "kN": (1e3, _NEWTON),
    "Pa": (1.0, _PASCAL),
    "kPa": (1e3, _PASCAL),
    "MPa": (1e6, _PASCAL),
    "bar": (1e5, _PASCAL),
    "mbar": (1e2, _PASCAL),
    "J": (1.0, _JOULE),
    "W": (1.0, {"kg": 1, "m": 2, "s": -3}),
    "V": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -1}),
    "Ohm": (1.0, {"kg": 1, "m": 2, "s": -3, "A": -2}),
}

_TERM = re.compile(r"^([A-Za-z]+)(-?\d+)?$")


@dataclass(frozen=True)
class UnitDefinition:
    """One FMI ``<Unit>``: its name as written on variables and its SI expression.

    Parameters
    ----------
    name : str
        The unit string, e.g. ``"N.m.s/rad"``.
    factor : float
        Value in SI base units of one of this unit (``1e5`` for ``"bar"``).
    exponents : tuple of (str, int)
        Non-zero base-unit exponents in :data:`BASE_UNITS` order.
    """

    name: str
    factor: float
    exponents: tuple[tuple[str, int], ...]


def _split_terms(unit: str) -> tuple[list[tuple[str, int]], list[tuple[str, int]]]:
    """Numerator and denominator terms ``(symbol, power)`` of a unit string."""
    if not isinstance(unit, str) or not unit.strip():
        raise ValueError(f"unit {unit!r}: a unit must be a non-empty string (use '1' if none)")
    parts = unit.strip().split("/")
    if len(parts) > 2:
        raise ValueError(f"unit {unit!r}: at most one '/' is allowed")
    sides: list[list[tuple[str, int]]] = []
    for side_index, side in enumerate(parts):
        terms = []
        for token in side.split("."):
            match = _TERM.match(token)
            if token == "1" and side_index == 0:
                continue
            if match is None:
                raise ValueError(f"unit {unit!r}: cannot read the term {token!r} "
                                 "(expected a symbol with an optional integer power, e.g. 'm2')")
            terms.append((match.group(1), int(match.group(2) or 1)))
        sides.append(terms)
    return sides[0], sides[1] if len(sides) > 1 else []


def parse_unit(unit: str) -> UnitDefinition:
    """Translate a unit string into its FMI unit definition.

    Parameters
    ----------
    unit : str
        Unit in the project's notation, e.g. ``"N.m.s/rad"``.

    Returns
    -------
    UnitDefinition

    Raises
    ------
    ValueError
        If the string is malformed or uses a symbol not in :data:`SYMBOLS`.

    Examples
    --------
    >>> parse_unit("bar").factor
    100000.0
    """
    numerator, denominator = _split_terms(unit)
    factor = 1.0
    exponents = dict.fromkeys(BASE_UNITS, 0)
    for sign, terms in ((1, numerator), (-1, denominator)):
        for symbol, power in terms:
            if symbol not in SYMBOLS:
                raise ValueError(f"unit {unit!r}: unknown symbol {symbol!r} "
                                 f"(known: {', '.join(sorted(SYMBOLS))})")
            symbol_factor, symbol_exponents = SYMBOLS[symbol]
            factor *= symbol_factor ** (sign * power)
            for base, exponent in symbol_exponents.items():
                exponents[base] += sign * power * exponent
    return UnitDefinition(
        name=unit.strip(),
        factor=factor,
        exponents=tuple((base, exponents[base]) for base in BASE_UNITS if exponents[base]),
    )


def _format_terms(terms: list[tuple[str, int]]) -> str:
    return ".".join(symbol if power == 1 else f"{symbol}{power}" for symbol, power in terms)


def divide_unit_by_time(unit: str) -> str:
    """The unit of the time derivative of a quantity in ``unit``.

    Parameters
    ----------
    unit : str
        Unit of the quantity, e.g. ``"m"``, ``"rad/s"`` or ``"1"``.

    Returns
    -------
    str
        ``"m/s"``, ``"rad/s2"`` or ``"1/s"`` respectively.
    """
    numerator, denominator = _split_terms(unit)
    denominator_symbols = [symbol for symbol, _ in denominator]
    numerator_symbols = [symbol for symbol, _ in numerator]
    if "s" in denominator_symbols:
        i = denominator_symbols.index("s")
        denominator[i] = ("s", denominator[i][1] + 1)
    elif "s" in numerator_symbols:
        i = numerator_symbols.index("s")
        numerator[i] = ("s", numerator[i][1] - 1)
        numerator = [term for term in numerator if term[1] != 0]
    else:
        denominator.append(("s", 1))
    text = _format_terms(numerator) or "1"
    return f"{text}/{_format_terms(denominator)}" if denominator else text


def collect_unit_definitions(units: Iterable[str | None]) -> tuple[UnitDefinition, ...]:
    """Unit definitions for every distinct unit used, sorted by name (``None`` is skipped).

    Parameters
    ----------
    units : iterable of str or None
        The units of all variables.

    Returns
    -------
    tuple of UnitDefinition
    """
    names = sorted({unit for unit in units if unit is not None})
    return tuple(parse_unit(name) for name in names)
