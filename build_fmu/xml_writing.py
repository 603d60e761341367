"""Pieces shared by the FMI 2.0 and FMI 3.0 modelDescription.xml writers."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass

from panto.fmu_src.spec import ModelSpec

from .units import collect_unit_definitions
from .variables import LOG_CATEGORIES, FmuVariable

GENERATION_TOOL = "build_fmu (pantograph FMU builder)"


@dataclass(frozen=True)
class DefaultExperiment:
    """The DefaultExperiment of a model description (seconds).

    Read from ``spec.extra["default_experiment"]`` (keys ``start_time``, ``stop_time``,
    ``step_size``) when present.
    """

    start_time: float = 0.0
    stop_time: float = 1.0
    step_size: float = 1e-3


def read_default_experiment(spec: ModelSpec) -> DefaultExperiment:
    """The default experiment of a model, from ``spec.extra`` or the defaults.

    Parameters
    ----------
    spec : ModelSpec

    Returns
    -------
    DefaultExperiment
    """
    values = spec.extra.get("default_experiment", {})
    unknown = set(values) - {"start_time", "stop_time", "step_size"}
    if unknown:
        raise ValueError(f"model {spec.identifier}: extra['default_experiment'] has unknown "
                         f"keys {sorted(unknown)}")
    return DefaultExperiment(**{key: float(value) for key, value in values.items()})


def format_real(value: float) -> str:
    """Shortest round-trip text of a float, as xs:double."""
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    return repr(float(value))


def format_boolean(value: float | bool) -> str:
    """``"true"`` or ``"false"``."""
    return "true" if value else "false"


def add_unit_definitions(root: ElementTree.Element,
                         variables: tuple[FmuVariable, ...]) -> None:
    """Append ``<UnitDefinitions>`` for every unit used by a variable."""
    definitions = collect_unit_definitions(variable.unit for variable in variables)
    element = ElementTree.SubElement(root, "UnitDefinitions")
    for definition in definitions:
        unit = ElementTree.SubElement(element, "Unit", name=definition.name)
        attributes = {base: str(exponent) for base, exponent in definition.exponents}
        if definition.factor != 1.0:
            attributes["factor"] = format_real(definition.factor)
        if attributes:
            ElementTree.SubElement(unit, "BaseUnit", attributes)


def add_log_categories(root: ElementTree.Element) -> None:
    """Append ``<LogCategories>`` (the categories the runtime knows)."""
    element = ElementTree.SubElement(root, "LogCategories")
    for name, description in LOG_CATEGORIES:
        ElementTree.SubElement(element, "Category", name=name, description=description)


def add_default_experiment(root: ElementTree.Element, spec: ModelSpec) -> None:
    """Append ``<DefaultExperiment>``."""
    experiment = read_default_experiment(spec)
    ElementTree.SubElement(root, "DefaultExperiment", startTime=format_real(
        experiment.start_time), stopTime=format_real(experiment.stop_time),
        stepSize=format_real(experiment.step_size))


def format_bounds(variable: FmuVariable) -> dict[str, str]:
    """``min``/``max`` attributes of a Real variable with a finite range."""
    attributes = {}
    if math.isfinite(variable.minimum):
        attributes["min"] = format_real(variable.minimum)
    if math.isfinite(variable.maximum):
        attributes["max"] = format_real(variable.maximum)
    return attributes


def render_xml(root: ElementTree.Element) -> str:
    """Indented XML text with declaration."""
    ElementTree.indent(root, space="  ")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            + ElementTree.tostring(root, encoding="unicode") + "\n")
