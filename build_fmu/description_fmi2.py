"""The FMI 2.0 modelDescription.xml (Model Exchange and Co-Simulation in one FMU).

Follows FMI 2.0.4 §2.2 (common), §3.3 (Model Exchange) and §4.3 (Co-Simulation): every
variable carries a unit, parameters are tunable with start/min/max, states have
``initial="approx"`` (overwritten by the static equilibrium unless ``start_in_equilibrium`` is
false), inputs carry their admissible range and states their nominal, and ``<ModelStructure>``
lists outputs, derivatives and initial unknowns with their exact dependencies and
``dependenciesKind`` (1-based indices into ``<ModelVariables>``; from the symbolic Jacobian,
:mod:`panto.fmu_src.sparsity`). ``numberOfEventIndicators`` counts the contact event indicators.

The independent variable ``time`` is not listed: FMI 2.0.4 §2.2.7 makes it implicit (name
``time``, unit s) when no variable is ``independent``, and FMI Library (in libcosim, among others)
wrongly demands a start value of a listed one (which the standard forbids). Its value reference
0 stays reserved, so the indices are positions in the list, not value references + 1.
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
    "canNotUseMemoryManagementFunctions": "false",
    "canGetAndSetFMUstate": "true",
    "canSerializeFMUstate": "true",
    "providesDirectionalDerivative": "true",
}


def _add_interfaces(root: ElementTree.Element, spec: ModelSpec,
                    source_files: tuple[str, ...]) -> None:
    model_exchange = ElementTree.SubElement(root, "ModelExchange", {
        "modelIdentifier": spec.identifier, **_COMMON_CAPABILITIES,
        "completedIntegratorStepNotNeeded": "true"})
    co_simulation = ElementTree.SubElement(root, "CoSimulation", {
        "modelIdentifier": spec.identifier, **_COMMON_CAPABILITIES,
        "canHandleVariableCommunicationStepSize": "true",
        "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0",
        "canRunAsynchronuously": "false"})
    for interface in (model_exchange, co_simulation):
        files = ElementTree.SubElement(interface, "SourceFiles")
        for name in source_files:
            if name.endswith(".c"):
                ElementTree.SubElement(files, "File", name=name)


def _listed(variables: tuple[FmuVariable, ...]) -> tuple[FmuVariable, ...]:
    """The variables of ``<ModelVariables>``: all but the implicit independent ``time``."""
    return tuple(variable for variable in variables if variable.kind != "time")


def _indices(variables: tuple[FmuVariable, ...]) -> dict[int, int]:
    """The 1-based ``<ModelVariables>`` index of each listed variable, by value reference."""
    return {variable.value_reference: position + 1
            for position, variable in enumerate(_listed(variables))}


def _type_element(variable: FmuVariable, indices: dict[int, int]) -> tuple[str, dict[str, str]]:
    if variable.type == "Boolean":
        attributes = {}
        if variable.start is not None:
            attributes["start"] = format_boolean(variable.start)
        return "Boolean", attributes
    attributes = {"unit": variable.unit} if variable.unit else {}
    if variable.start is not None:
        attributes["start"] = format_real(variable.start)
    attributes.update(format_bounds(variable))
    if variable.nominal is not None:
        attributes["nominal"] = format_real(variable.nominal)
    if variable.derivative_of is not None:
        attributes["derivative"] = str(indices[variable.derivative_of])
    return "Real", attributes


def _add_variables(root: ElementTree.Element, variables: tuple[FmuVariable, ...]) -> None:
    element = ElementTree.SubElement(root, "ModelVariables")
    indices = _indices(variables)
    for variable in _listed(variables):
        attributes = {"name": variable.name, "valueReference": str(variable.value_reference),
                      "description": variable.description, "causality": variable.causality,
                      "variability": variable.variability}
        if variable.initial is not None:
            attributes["initial"] = variable.initial
        scalar = ElementTree.SubElement(element, "ScalarVariable", attributes)
        tag, type_attributes = _type_element(variable, indices)
        ElementTree.SubElement(scalar, tag, type_attributes)


def _unknown(parent: ElementTree.Element, variable: FmuVariable, indices: dict[int, int],
             dependencies: tuple[tuple[FmuVariable, str], ...] | None) -> None:
    attributes = {"index": str(indices[variable.value_reference])}
    if dependencies is not None:
        attributes["dependencies"] = " ".join(str(indices[v.value_reference])
                                              for v, _ in dependencies)
        attributes["dependenciesKind"] = " ".join(kind for _, kind in dependencies)
    ElementTree.SubElement(parent, "Unknown", attributes)


def _add_model_structure(root: ElementTree.Element, spec: ModelSpec,
                         variables: tuple[FmuVariable, ...]) -> None:
    structure = ElementTree.SubElement(root, "ModelStructure")
    indices = _indices(variables)
    outputs = ElementTree.SubElement(structure, "Outputs")
    for variable in variables:
        if variable.kind == "output":
            _unknown(outputs, variable, indices,
                     list_dependencies(variable, variables, spec.dependencies))
    derivatives = ElementTree.SubElement(structure, "Derivatives")
    for variable in variables:
        if variable.kind == "derivative":
            _unknown(derivatives, variable, indices,
                     list_dependencies(variable, variables, spec.dependencies))
    initial = ElementTree.SubElement(structure, "InitialUnknowns")
    for variable in variables:  # ascending index, as FMI 2.0 requires
        if variable.kind in ("state", "derivative", "output"):
            _unknown(initial, variable, indices, None)  # no attribute: depends on all knowns


def write_model_description_fmi2(spec: ModelSpec, variables: tuple[FmuVariable, ...],
                                 token: str, source_files: tuple[str, ...]) -> str:
    """Render the FMI 2.0 modelDescription.xml.

    Parameters
    ----------
    spec : ModelSpec
        The model.
    variables : tuple of FmuVariable
        Its variable table (:func:`panto.build_fmu.variables.layout_variables`).
    token : str
        The GUID, ``{8-4-4-4-12}`` hexadecimal.
    source_files : tuple of str
        Names of the files in ``sources/`` (the ``.c`` files are listed).

    Returns
    -------
    str
        The XML text.
    """
    root = ElementTree.Element("fmiModelDescription", {
        "fmiVersion": "2.0",
        "modelName": spec.identifier,
        "guid": token,
        "description": spec.description,
        "generationTool": GENERATION_TOOL,
        "variableNamingConvention": "flat",
        "numberOfEventIndicators": str(len(spec.active_event_indicators))})
    _add_interfaces(root, spec, source_files)
    add_unit_definitions(root, variables)
    add_log_categories(root)
    add_default_experiment(root, spec)
    _add_variables(root, variables)
    _add_model_structure(root, spec, variables)
    return render_xml(root)
