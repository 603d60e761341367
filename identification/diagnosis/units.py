"""Units of the effect parameters a diagnosis fits, derived from their names and the data's units.

An effect's parameters are named ``effect:signal[:part]`` (:mod:`~panto.identification.diagnosis.augmentations`)
or, where the nominal structure carries the effect itself, by the structure's own name. The unit
follows from what the parameter does to the signal it names:

=============================  ====================================================================
``input_delay:u``              a delay [s]
``actuator_lag:u``             a time constant [s]
``dead_zone:u``                a half width of input ``u`` (its unit)
``saturation:s:low``/``high``  a level of signal ``s`` (its unit)
``offset:y``                   added to output ``y`` (its unit)
``coulomb_friction:s``         added to ``s``: the force output, or the input through which the
                               friction acts as an equivalent input (its unit)
``coulomb_friction:presliding``  the presliding width, a position [m]
``cubic_stiffness:y``          times the position cubed: ``y``'s unit per m^3
``sensor_inertia:y``           times the sensor's acceleration: ``y``'s unit per (m/s^2), kg for
                               a force in N
``extra_mode:gain``            the target output's unit per unit of the drive signal
``extra_mode:frequency``       [Hz]
``extra_mode:damping``         damping ratio [-]
``T_f``, ``k_c3``              hinge friction torque [N m], cubic contact stiffness [N/m^3]
``F_f1..3``, ``kc1..3``        friction force on mass i [N], cubic spring coefficient [1/m^2]
``kq1..3``                     quadratic spring coefficient [1/m]
``m_e``, ``f_e``, ``zeta_e``   a mass hung on an oscillator's head [kg], its frequency with the
                               head held [Hz], its damping ratio [-]
=============================  ====================================================================

A unit that cannot be derived (a signal without a unit in the data, an unknown name) is ``?``.

Examples
--------
>>> effect_parameter_unit("saturation:F_c:low", {"F_c": "N"})
'N'
>>> effect_parameter_unit("extra_mode:gain", {"F_c": "N", "eta": "m"}, output="F_c",
...                       drive="eta")
'N/m'
"""
from __future__ import annotations

import re
from typing import Mapping

#: Units of the effect parameters that the nominal structures carry under their own names.
NATIVE_UNITS = {"T_f": "N m", "k_c3": "N/m^3", "v_eps": "m/s", "m_e": "kg", "f_e": "Hz",
                "zeta_e": "-"}
#: Per-mass parameters of the oscillators' inside effects: name pattern -> unit.
PER_MASS_UNITS = {r"F_f\d+": "N", r"kc\d+": "1/m^2", r"kq\d+": "1/m"}
#: Effects whose parameter ``effect:signal`` is added to (or is a level of) that signal.
SIGNAL_LEVEL_EFFECTS = ("dead_zone", "saturation", "offset", "coulomb_friction")
#: Unit of a quantity that cannot be derived.
UNKNOWN = "?"


def effect_parameter_unit(name: str, units: Mapping[str, str], *, output: str | None = None,
                          drive: str | None = None, position_unit: str = "m") -> str:
    """The unit of effect parameter `name` (module notes).

    Parameters
    ----------
    name : str
        The parameter, e.g. ``"input_delay:eta"``, ``"saturation:F_c:low"``, ``"T_f"``.
    units : mapping of str to str
        The data's units by signal name (:attr:`IdentificationData.units`).
    output : str, optional
        The target output of an ``extra_mode`` (its gain's numerator).
    drive : str, optional
        The drive signal of an ``extra_mode`` (its gain's denominator).
    position_unit : str
        The unit of the position signal that the friction's presliding width, the cubic
        stiffness and the sensor's acceleration are taken from (default m).

    Returns
    -------
    str
        The unit, ``-`` for a dimensionless parameter, ``?`` when it cannot be derived.
    """
    effect, _, rest = name.partition(":")
    if not rest:
        return NATIVE_UNITS.get(name) or next(
            (unit for pattern, unit in PER_MASS_UNITS.items() if re.fullmatch(pattern, name)),
            UNKNOWN)
    signal = rest.split(":")[0]
    if effect in ("input_delay", "actuator_lag"):
        return "s"
    if effect == "extra_mode":
        return {"frequency": "Hz", "damping": "-"}.get(signal) or _ratio(
            _unit(units, output), _unit(units, drive))
    if effect == "coulomb_friction" and signal == "presliding":
        return position_unit
    if effect in SIGNAL_LEVEL_EFFECTS:
        return _unit(units, signal)
    if effect == "cubic_stiffness":
        return _ratio(_unit(units, signal), f"{position_unit}^3")
    if effect == "sensor_inertia":
        force = _unit(units, signal)
        return "kg" if (force, position_unit) == ("N", "m") else _ratio(
            force, f"({position_unit}/s^2)")
    return UNKNOWN


def effect_parameter_units(names, units: Mapping[str, str], **context: str | None
                           ) -> dict[str, str]:
    """:func:`effect_parameter_unit` of every name in `names` (same `context` for all)."""
    return {name: effect_parameter_unit(name, units, **context) for name in names}


def _unit(units: Mapping[str, str], signal: str | None) -> str:
    unit = units.get(signal) if signal else None
    return str(unit) if unit else UNKNOWN


def _ratio(numerator: str, denominator: str) -> str:
    if UNKNOWN in (numerator, denominator):
        return UNKNOWN
    return f"{numerator}/{denominator}"
