"""The FMI 3.0 modelDescription.xml and sources/buildDescription.xml.

Follows FMI 3.0.1 §2.4 (model description), §3.3 (Model Exchange), §4.3 (Co-Simulation) and
§2.5.1 (build description): Float64/Boolean variables with units, ``derivative`` attributes
on the state derivatives, ``<ModelStructure>`` with outputs, continuous-state derivatives
(exact dependencies as value references, with ``dependenciesKind``), initial unknowns and event
indicators.
"""
from __future__ import annotations

import xml.etree.ElementTree as ElementTree

from panto.fmu_src.spec import ModelSpec

from .variables import FmuVariable, list_dependencies
from .xml_writing import (GENERATION_TOOL, add_default_experiment, add_log_categories,
                          add_unit_definitions, format_bounds, format_boolean, format_real,
                          render_xml)

_COMMON_CAPABILITIES = {
    "needsExecutionTool": "false",
    "canBeInstantiatedOnlyOncePerProcess": "false",
    "canGetAndSetFMUState": "true",
    "canSerializeFMUState": "true",
    "providesDirectionalDerivatives": "true",
    "providesAdjointDerivatives": "true",
}


def _add_interfaces(root: ElementTree.Element, spec: ModelSpec) -> None:
    ElementTree.SubElement(root, "ModelExchange", {
        "modelIdentifier": spec.identifier, **_COMMON_CAPABILITIES,
        "needsCompletedIntegratorStep": "false"})
    ElementTree.SubElement(root, "CoSimulation", {
        "modelIdentifier": spec.identifier, **_COMMON_CAPABILITIES,
        "canHandleVariableCommunicationStepSize": "true",
        "maxOutputDerivativeOrder": "0",
        "hasEventMode": "true",
        "providesIntermediateUpdate": "false",
        "canReturnEarlyAfterIntermediateUpdate": "false"})


def _variable_attributes(variable: FmuVariable) -> dict[str, str]:
    attributes = {"name": variable.name, "valueReference": str(variable.value_reference),
                  "description": variable.description, "causality": variable.causality,
                  "variability": variable.variability}
    if variable.initial is not None:
        attributes["initial"] = variable.initial
    if variable.type == "Boolean":
        if variable.start is not None:
            attributes["start"] = format_boolean(variable.start)
        return attributes
    if variable.unit:
        attributes["unit"] = variable.unit
    if variable.start is not None:
        attributes["start"] = format_real(variable.start)
    attributes.update(format_bounds(variable))
    if variable.nominal is not None:
        attributes["nominal"] = format_real(variable.nominal)
    if variable.derivative_of is not None:
        attributes["derivative"] = str(variable.derivative_of)
    return attributes


def _add_variables(root: ElementTree.Element, variables: tuple[FmuVariable, ...]) -> None:
    element = ElementTree.SubElement(root, "ModelVariables")
    for variable in variables:
        tag = "Boolean" if variable.type == "Boolean" else "Float64"
        ElementTree.SubElement(element, tag, _variable_attributes(variable))


def _unknown(parent: ElementTree.Element, tag: str, variable: FmuVariable,
             dependencies: tuple[tuple[FmuVariable, str], ...] | None) -> None:
    attributes = {"valueReference": str(variable.value_reference)}
    if dependencies is not None:
        attributes["dependencies"] = " ".join(str(v.value_reference) for v, _ in dependencies)
        attributes["dependenciesKind"] = " ".join(kind for _, kind in dependencies)
    ElementTree.SubElement(parent, tag, attributes)


def _add_model_structure(root: ElementTree.Element, spec: ModelSpec,
                         variables: tuple[FmuVariable, ...]) -> None:
    structure = ElementTree.SubElement(root, "ModelStructure")
    for variable in variables:
        if variable.kind == "output":
            _unknown(structure, "Output", variable,
                     list_dependencies(variable, variables, spec.dependencies))
    for variable in variables:
        if variable.kind == "derivative":
            _unknown(structure, "ContinuousStateDerivative", variable,
                     list_dependencies(variable, variables, spec.dependencies))
    for variable in variables:
        if variable.kind in ("state", "derivative", "output"):
            _unknown(structure, "InitialUnknown", variable, None)
    for variable in variables:
        if variable.kind == "event_indicator":
            ElementTree.SubElement(structure, "EventIndicator",
                                   {"valueReference": str(variable.value_reference)})


def write_model_description_fmi3(spec: ModelSpec, variables: tuple[FmuVariable, ...],
                                 token: str) -> str:
    """Render the FMI 3.0 modelDescription.xml.

    Parameters
    ----------
    spec : ModelSpec
        The model.
    variables : tuple of FmuVariable
        Its variable table (:func:`panto.build_fmu.variables.layout_variables`).
    token : str
        The instantiation token.

    Returns
    -------
    str
        The XML text.
    """
    root = ElementTree.Element("fmiModelDescription", {
        "fmiVersion": "3.0",
        "modelName": spec.identifier,
        "instantiationToken": token,
        "description": spec.description,
        "generationTool": GENERATION_TOOL,
        "variableNamingConvention": "flat"})
    _add_interfaces(root, spec)
    add_unit_definitions(root, variables)
    add_log_categories(root)
    add_default_experiment(root, spec)
    _add_variables(root, variables)
    _add_model_structure(root, spec, variables)
    return render_xml(root)


def write_build_description(spec: ModelSpec, source_files: tuple[str, ...]) -> str:
    """Render ``sources/buildDescription.xml`` (all sources in one C99 file set).

    Parameters
    ----------
    spec : ModelSpec
        The model.
    source_files : tuple of str
        Names of the files in ``sources/`` (the ``.c`` files are listed).

    Returns
    -------
    str
        The XML text.
    """
    root = ElementTree.Element("fmiBuildDescription", fmiVersion="3.0")
    configuration = ElementTree.SubElement(root, "BuildConfiguration",
                                           modelIdentifier=spec.identifier)
    file_set = ElementTree.SubElement(configuration, "SourceFileSet", language="C99")
    for name in source_files:
        if name.endswith(".c"):
            ElementTree.SubElement(file_set, "SourceFile", name=name)
    return render_xml(root)
