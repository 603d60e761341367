"""Parameter sets as data: values with units, admissible bounds and provenance, saved as JSON.

A parameter file is a JSON object a person can read and edit::

    {"model": "Pantograph",
     "parameters": {"m1": {"value": 22.1, "unit": "kg", "minimum": 1e-06, "maximum": 10000.0,
                           "provenance": "thesis Table 4.1 ..."}, ...}}

Only ``value`` is required per entry; parameters left out keep their defaults. Values outside the
admissible range are refused with an error naming the file, the parameter, the value and the range.
A ``unit`` other than the model's is converted when it is a plain multiple of it (``g`` for
``kg``, ``mm`` for ``m``, ``deg`` for ``rad``, ``kN/m`` for ``N/m``: :data:`UNIT_CONVERSIONS`)
and refused otherwise, never ignored.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

from panto.fmu_src.spec import ParameterSpec


class ParameterError(ValueError):
    """A parameter value or parameter file is not admissible."""


#: Units a parameter file may use instead of the model's: unit -> (model's unit, factor to it).
UNIT_CONVERSIONS: Mapping[str, tuple[str, float]] = MappingProxyType({
    "g": ("kg", 1e-3), "mm": ("m", 1e-3), "cm": ("m", 1e-2), "deg": ("rad", math.pi / 180.0),
    "kN": ("N", 1e3), "kN/m": ("N/m", 1e3), "N/mm": ("N/m", 1e3), "kN.s/m": ("N.s/m", 1e3)})


def _unit_key(unit: str) -> str:
    """One spelling of a unit: ``"N m"``, ``"N*m"`` and ``"N·m"`` are ``"N.m"``; ``^`` dropped."""
    key = ".".join(unit.split())
    for mark in ("*", "\u00b7"):
        key = key.replace(mark, ".")
    return key.replace("^", "")


def _in_model_unit(value: float, unit: object, spec: ParameterSpec, path: Path) -> float:
    """`value` given in `unit`, in the model's unit of `spec` (converted or refused)."""
    if unit is None or _unit_key(str(unit)) == _unit_key(spec.unit):
        return value
    target, factor = UNIT_CONVERSIONS.get(_unit_key(str(unit)), (None, 1.0))
    if target is not None and _unit_key(target) == _unit_key(spec.unit):
        return value * factor
    convertible = sorted(u for u, (t, _) in UNIT_CONVERSIONS.items() if t == spec.unit)
    raise ParameterError(f"{path}: parameter {spec.name!r} is given in {unit!r}; its unit is "
                         f"{spec.unit!r}" + (f" (or {', '.join(convertible)})" if convertible
                                             else ""))


@dataclass(frozen=True)
class ParameterSet:
    """Values for every parameter of one model, checked against their admissible ranges.

    Parameters
    ----------
    model : str
        Model name (``"Pantograph"``, ``"TwoMass"``, ...).
    specs : tuple of ParameterSpec
        The model's parameters (order, unit, bounds, provenance, default).
    values : mapping
        Name -> value; defaults are used for missing names.

    Examples
    --------
    >>> from panto.fmu_src.models import default_parameters
    >>> params = default_parameters("Pantograph").with_values(k_ph=50000.0)
    >>> params["k_ph"]
    50000.0
    """

    model: str
    specs: tuple[ParameterSpec, ...]
    values: Mapping[str, float] = field(default_factory=dict)
    source: str = "defaults"

    def __post_init__(self):
        known = {s.name: s for s in self.specs}
        unknown = sorted(set(self.values) - set(known))
        if unknown:
            raise ParameterError(
                f"{self.source}: unknown parameter(s) {unknown} for model {self.model}; "
                f"known: {sorted(known)}")
        full = {}
        for spec in self.specs:
            value = self.values.get(spec.name, spec.value)
            full[spec.name] = _checked(spec, value, self.source)
        object.__setattr__(self, "values", MappingProxyType(full))

    # --- access ---------------------------------------------------------------------------
    def __getitem__(self, name: str) -> float:
        return self.values[name]

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order."""
        return tuple(s.name for s in self.specs)

    def vector(self) -> np.ndarray:
        """Values in the order of the model's parameter vector."""
        return np.array([self.values[s.name] for s in self.specs], dtype=float)

    def spec(self, name: str) -> ParameterSpec:
        """The specification (unit, bounds, provenance) of one parameter."""
        for s in self.specs:
            if s.name == name:
                return s
        raise KeyError(f"model {self.model} has no parameter {name!r}")

    def with_values(self, values: Mapping[str, float] | None = None, /, **changes: float) -> ParameterSet:
        """A copy with some values changed (validated)."""
        merged = dict(self.values)
        merged.update(values or {})
        merged.update(changes)
        return ParameterSet(self.model, self.specs, merged, source="changed values")

    # --- files ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-ready representation with units, bounds and provenance."""
        entries = {}
        for s in self.specs:
            entry = {"value": self.values[s.name], "unit": s.unit, "description": s.description,
                     "minimum": _json_number(s.minimum), "maximum": _json_number(s.maximum),
                     "provenance": s.provenance}
            if s.boolean:
                entry["boolean"] = True
            entries[s.name] = entry
        return {"model": self.model, "parameters": entries}

    def save(self, path: str | Path) -> Path:
        """Write the parameter set as JSON."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path, specs: tuple[ParameterSpec, ...], model: str) -> ParameterSet:
        """Read a parameter file for ``model`` (see the module docstring for the format)."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as error:
            raise ParameterError(f"{path}: cannot read parameter file ({error})") from error
        if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
            raise ParameterError(f"{path}: expected an object with a 'parameters' object")
        if data.get("model", model) != model:
            raise ParameterError(f"{path}: parameters are for model {data['model']!r}, not {model!r}")
        values, known = {}, {s.name: s for s in specs}
        for name, entry in data["parameters"].items():
            value = entry.get("value") if isinstance(entry, dict) else entry
            if not isinstance(value, (int, float)):  # JSON true/false count as 1/0
                raise ParameterError(f"{path}: parameter {name!r} has no numeric 'value' ({entry!r})")
            values[name] = float(value)
            if name in known and isinstance(entry, dict):
                values[name] = _in_model_unit(values[name], entry.get("unit"), known[name], path)
        return cls(model, specs, values, source=str(path))


def _checked(spec: ParameterSpec, value, source: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{source}: parameter {spec.name!r} = {value!r} is not a number") from None
    if not math.isfinite(number):
        raise ParameterError(f"{source}: parameter {spec.name!r} = {number} is not finite")
    if spec.boolean and number not in (0.0, 1.0):
        raise ParameterError(f"{source}: parameter {spec.name!r} is a switch (0 or 1), got {number}")
    if not spec.minimum <= number <= spec.maximum:
        raise ParameterError(
            f"{source}: parameter {spec.name!r} = {number:g} {spec.unit} is outside its admissible "
            f"range [{spec.minimum:g}, {spec.maximum:g}] ({spec.description})")
    return number


def _json_number(x: float) -> float | None:
    return x if math.isfinite(x) else None
