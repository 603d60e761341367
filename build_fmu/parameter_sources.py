"""Where an FMU's parameter values come from: a mapping, a parameter file or an identification result.

:func:`fmu_parameter_values` turns any of the three into the ``{name: value}`` that
:meth:`panto.build_fmu.simulate.FmuSimulator.simulate` and the co-simulation's pantograph set-up
(:meth:`panto.catenary_cosim.pantographs.PantographSetup.with_parameters`) set, so that an
identification's result, or the ``parameters.json`` that ``panto identify --out`` writes, can be
passed on directly:

mapping
    Taken as it is (the simulator checks the names).
parameter file (``str`` or :class:`pathlib.Path`)
    JSON ``{"model": ..., "parameters": {name: {"value": v, "unit": u}}}``
    (:meth:`panto.fmu_src.parameters.ParameterSet.to_dict`). When ``model`` is one of the project's
    models, the file is read with that model's specifications: units are converted to the
    model's (``g`` to ``kg``, ``mm`` to ``m``, ...) or refused, values outside the admissible
    range refused, and the model must be of the FMU's family (``Pantograph`` for
    ``Pantograph``, ``PantographLinear`` and ``PantographForce``; a ``TwoMass`` file is refused for
    a ``ThreeMass`` FMU although the names overlap); names of the file that this variant of the
    model lacks are left out. Any other file is read by name: every name must be a parameter of
    the FMU, and a unit, when given, must be the FMU's.
identification result
    Any object with a ``parameters`` mapping (an
    :class:`panto.identification.estimation.base.IdentificationResult`): the values of the
    parameters the FMU has. Every *estimated* parameter (``free``) must be one of them, otherwise
    the result is of another model and is refused; fixed parameters of the structure that are not
    model parameters (the measurement delay ``eta_delay`` of the physical structures) are left
    out.
"""
from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

#: Suffixes stripped to find a model's family: the linearised and force-excited variants share
#: the parameters of the model they come from.
_VARIANT_SUFFIXES = ("Linear", "Force")


def model_family(model: str) -> str:
    """The model a variant comes from: ``"PantographForceLinear"`` -> ``"Pantograph"``.

    Examples
    --------
    >>> model_family("PantographForceLinear"), model_family("TwoMassForce"), model_family("ThreeMass")
    ('Pantograph', 'TwoMass', 'ThreeMass')
    """
    name = model
    stripped = True
    while stripped:
        stripped = False
        for suffix in _VARIANT_SUFFIXES:
            if name.endswith(suffix) and len(name) > len(suffix):
                name, stripped = name[:-len(suffix)], True
    return name


def fmu_parameter_values(source: Any, *, model: str, parameter_names: Sequence[str],
                         units: Mapping[str, str] | None = None) -> dict[str, Any]:
    """Parameter values for an FMU from a mapping, a parameter file or an identification result.

    Parameters
    ----------
    source : mapping, str, pathlib.Path, identification result or None
        See the module notes. None gives no values.
    model : str
        The FMU's model name (``modelName`` of its model description).
    parameter_names : sequence of str
        The FMU's parameters.
    units : mapping of str to str, optional
        The FMU's unit of each parameter (checked against a plain file's units).

    Returns
    -------
    dict
        Parameter name -> value, in the FMU's units.

    Raises
    ------
    ValueError
        For a file that cannot be read or is for another model, a unit that cannot be
        converted, a value out of range (the message names the file, parameter and value), or a
        result whose estimated parameters the FMU does not have.
    TypeError
        For any other kind of `source`.
    """
    if source is None:
        return {}
    if isinstance(source, Mapping):
        return dict(source)
    if isinstance(source, (str, os.PathLike)):
        return _from_file(Path(source), model, tuple(parameter_names), dict(units or {}))
    if isinstance(getattr(source, "parameters", None), Mapping):
        return _from_result(source, model, tuple(parameter_names))
    raise TypeError(f"parameters must be a mapping, a parameter file or an identification "
                    f"result, got {type(source).__name__}")


def _from_file(path: Path, model: str, names: tuple[str, ...],
               units: dict[str, str]) -> dict[str, Any]:
    """Values from a parameter file (module notes)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"{path}: cannot read the parameter file ({error})") from None
    if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
        raise ValueError(f"{path}: expected an object with a 'parameters' object")
    file_model = data.get("model")
    from panto.fmu_src.models import MODEL_NAMES, default_parameters
    from panto.fmu_src.parameters import ParameterSet

    if file_model in MODEL_NAMES:
        if model_family(file_model) != model_family(model):
            raise ValueError(f"{path}: parameters are for model {file_model!r}; the FMU is "
                             f"{model!r}")
        loaded = ParameterSet.load(path, default_parameters(file_model).specs, file_model)
        return {name: loaded.values[name] for name in data["parameters"] if name in names}
    unknown = sorted(set(data["parameters"]) - set(names))
    if unknown:
        raise ValueError(f"{path}: {unknown} are not parameters of the FMU {model!r} (its: "
                         f"{', '.join(names)})")
    values = {}
    for name, entry in data["parameters"].items():
        value = entry.get("value") if isinstance(entry, dict) else entry
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{path}: parameter {name!r} has no numeric value ({value!r})")
        unit = entry.get("unit") if isinstance(entry, dict) else None
        if unit and units.get(name) and unit != units[name]:
            raise ValueError(f"{path}: parameter {name!r} is given in {unit!r}; the FMU's unit "
                             f"is {units[name]!r}")
        values[name] = float(value)
    return values


def _from_result(result: Any, model: str, names: tuple[str, ...]) -> dict[str, Any]:
    """Values from an identification result (module notes)."""
    parameters = dict(result.parameters)
    missing = [name for name in getattr(result, "free", parameters) if name not in names]
    if missing:
        structure = getattr(result, "structure", type(result).__name__)
        raise ValueError(f"the {structure} result estimated {missing}, which are not parameters "
                         f"of the FMU {model!r}: it is a result for another model")
    return {name: float(value) for name, value in parameters.items() if name in names}


__all__ = ["fmu_parameter_values", "model_family"]
