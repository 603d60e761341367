"""The FMU's variable table: one row per FMI variable, shared by the XML writers and the C table.

The value reference of a variable is its row number, in this order::

    time | states x = [q; v] | their derivatives | inputs u | outputs y | parameters p
         | operating points u0 (linearised models only) | solver_tolerance | start_in_equilibrium
         | event indicators z (models with events, not linearised)

The runtime (``fmu_src/runtime/fmu_core.c``) reads the same table from the generated
``model_config.h``, so the two sides cannot disagree.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

from panto.fmu_src.spec import ModelSpec

from .units import divide_unit_by_time

#: Name of the Real parameter holding the co-simulation solver's tolerance.
SOLVER_TOLERANCE_NAME = "solver_tolerance"
#: Name of the Boolean parameter choosing the initial state.
START_IN_EQUILIBRIUM_NAME = "start_in_equilibrium"
#: Prefix of the states of a linearised model (deviations from the equilibrium).
DEVIATION_PREFIX = "delta_"
#: Suffix of the operating-point parameter of each input of a linearised model.
OPERATING_POINT_SUFFIX = "0"

#: Log categories of the runtime, in the order of ``LOG_CATEGORIES`` in ``fmu_core.c``.
LOG_CATEGORIES: tuple[tuple[str, str], ...] = (
    ("logStatusError", "Errors: refused arguments and failed computations"),
    ("logStatusWarning", "Warnings"),
    ("logEvents", "Mode changes"),
    ("logNonlinearSystems", "Newton iterations of the static equilibrium"),
    ("logSolver", "Co-simulation integrator: sub-steps and step sizes"),
    ("logStatusDiscard", "Discarded co-simulation steps (a numerical limit, the FMU can go on)"),
)

_C_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class FmuVariable:
    """One FMI variable and where the runtime keeps its value.

    Parameters
    ----------
    name, description : str
        As shown in the modelDescription.xml.
    value_reference : int
        Row number in the table (FMI 2.0 index = value_reference, as the implicit ``time``
        with value reference 0 is not listed there).
    kind : str
        ``"time"``, ``"state"``, ``"derivative"``, ``"input"``, ``"output"``, ``"parameter"``,
        ``"operating_point"``, ``"solver_tolerance"``, ``"start_in_equilibrium"`` or
        ``"event_indicator"``.
    index : int
        Position within the runtime vector of that kind (x, u, y, p, u0).
    type : str
        ``"Real"`` or ``"Boolean"``.
    causality, variability : str
        FMI causality and variability.
    initial : str or None
        FMI ``initial`` attribute, ``None`` to leave it out.
    start : float or None
        Start value (``None``: no start attribute).
    minimum, maximum : float
        Admissible range (infinite: no attribute).
    unit : str or None
        Unit string (``None`` for Booleans).
    derivative_of : int or None
        For a state derivative, the value reference of its state.
    nominal : float or None
        FMI ``nominal`` (states; ``None``: no attribute, i.e. 1).
    """

    name: str
    description: str
    value_reference: int
    kind: str
    index: int
    type: str
    causality: str
    variability: str
    initial: str | None
    start: float | None
    minimum: float = -math.inf
    maximum: float = math.inf
    unit: str | None = None
    derivative_of: int | None = None
    nominal: float | None = None


def _check_spec(spec: ModelSpec) -> None:
    if not _C_IDENTIFIER.match(spec.identifier):
        raise ValueError(f"model identifier {spec.identifier!r} is not a valid C identifier")
    if len(spec.coordinates) != len(spec.velocities) or not spec.coordinates:
        raise ValueError(f"model {spec.identifier}: {len(spec.coordinates)} coordinates but "
                         f"{len(spec.velocities)} velocities (need the same, at least one)")
    for parameter in spec.parameters:
        if not parameter.minimum <= parameter.value <= parameter.maximum:
            raise ValueError(f"model {spec.identifier}: parameter {parameter.name!r} = "
                             f"{parameter.value} is outside its range "
                             f"[{parameter.minimum}, {parameter.maximum}]")


def _state_rows(spec: ModelSpec, first: int) -> list[FmuVariable]:
    rows = []
    for i, state in enumerate(spec.states):
        name = f"{DEVIATION_PREFIX}{state.name}" if spec.linearised else state.name
        description = (f"Deviation from the equilibrium at the operating point: "
                       f"{state.description}" if spec.linearised else state.description)
        rows.append(FmuVariable(
            name=name, description=description, value_reference=first + i, kind="state",
            index=i, type="Real", causality="local", variability="continuous",
            initial="approx", start=0.0 if spec.linearised else float(state.start),
            unit=state.unit, nominal=state.nominal))
    return rows


def _derivative_rows(states: list[FmuVariable], first: int) -> list[FmuVariable]:
    return [FmuVariable(
        name=f"der({state.name})", description=f"Time derivative of {state.name}",
        value_reference=first + i, kind="derivative", index=i, type="Real", causality="local",
        variability="continuous", initial="calculated", start=None,
        unit=divide_unit_by_time(state.unit), derivative_of=state.value_reference)
        for i, state in enumerate(states)]


def _signal_rows(spec: ModelSpec, first: int) -> list[FmuVariable]:
    rows = []
    for i, signal in enumerate(spec.inputs):
        rows.append(FmuVariable(
            name=signal.name, description=signal.description, value_reference=first + i,
            kind="input", index=i, type="Real", causality="input", variability="continuous",
            initial=None, start=float(signal.start), minimum=float(signal.minimum),
            maximum=float(signal.maximum), unit=signal.unit))
    first += len(rows)
    for i, signal in enumerate(spec.outputs):
        rows.append(FmuVariable(
            name=signal.name, description=signal.description, value_reference=first + i,
            kind="output", index=i, type="Real", causality="output", variability="continuous",
            initial="calculated", start=None, unit=signal.unit))
    return rows


def _parameter_rows(spec: ModelSpec, first: int) -> list[FmuVariable]:
    rows = []
    for i, parameter in enumerate(spec.parameters):
        description = parameter.description
        if parameter.provenance:
            description = f"{description} [{parameter.provenance}]"
        rows.append(FmuVariable(
            name=parameter.name, description=description, value_reference=first + i,
            kind="parameter", index=i, type="Boolean" if parameter.boolean else "Real",
            causality="parameter", variability="tunable", initial=None,
            start=float(parameter.value), minimum=float(parameter.minimum),
            maximum=float(parameter.maximum),
            unit=None if parameter.boolean else parameter.unit))
    return rows


def _runtime_rows(spec: ModelSpec, first: int) -> list[FmuVariable]:
    rows = []
    if spec.linearised:
        for i, signal in enumerate(spec.inputs):
            rows.append(FmuVariable(
                name=f"{signal.name}{OPERATING_POINT_SUFFIX}",
                description=f"Operating point of input {signal.name} about which the model is "
                            "linearised",
                value_reference=first + i, kind="operating_point", index=i, type="Real",
                causality="parameter", variability="tunable", initial=None,
                start=float(signal.start), minimum=float(signal.minimum),
                maximum=float(signal.maximum), unit=signal.unit))
    first += len(rows)
    rows.append(FmuVariable(
        name=SOLVER_TOLERANCE_NAME,
        description="Tolerance of the co-simulation integrator (Rosenbrock RODAS4 with "
                    "error control): local error per sub-step below tol (1 + |x|); a smaller "
                    "tolerance given by the importer at set-up takes precedence",
        value_reference=first, kind="solver_tolerance", index=0, type="Real",
        causality="parameter", variability="tunable", initial=None, start=1e-6,
        minimum=1e-12, maximum=1e-2, unit="1"))
    rows.append(FmuVariable(
        name=START_IN_EQUILIBRIUM_NAME,
        description="true: the states start in the static equilibrium for the initial inputs "
                    "and parameters; false: the state start values are used as they are",
        value_reference=first + 1, kind="start_in_equilibrium", index=0, type="Boolean",
        causality="parameter", variability="fixed", initial=None, start=1.0))
    first += 2
    for i, indicator in enumerate(spec.active_event_indicators):
        rows.append(FmuVariable(
            name=indicator.name, description=f"Event indicator: {indicator.description}",
            value_reference=first + i, kind="event_indicator", index=i, type="Real",
            causality="local", variability="continuous", initial="calculated", start=None,
            unit=indicator.unit))
    return rows


def layout_variables(spec: ModelSpec) -> tuple[FmuVariable, ...]:
    """Lay out all FMI variables of a model with their value references.

    Parameters
    ----------
    spec : ModelSpec
        The model.

    Returns
    -------
    tuple of FmuVariable
        Ordered by value reference (0, 1, 2, ...).

    Raises
    ------
    ValueError
        If the identifier is not a C identifier, a name is used twice, or a default parameter
        value lies outside its range.
    """
    _check_spec(spec)
    rows = [FmuVariable(name="time", description="Simulation time", value_reference=0,
                        kind="time", index=0, type="Real", causality="independent",
                        variability="continuous", initial=None, start=None, unit="s")]
    states = _state_rows(spec, len(rows))
    rows += states
    rows += _derivative_rows(states, len(rows))
    rows += _signal_rows(spec, len(rows))
    rows += _parameter_rows(spec, len(rows))
    rows += _runtime_rows(spec, len(rows))
    seen: dict[str, FmuVariable] = {}
    for row in rows:
        if row.name in seen:
            raise ValueError(f"model {spec.identifier}: variable name {row.name!r} is used by "
                             f"both a {seen[row.name].kind} and a {row.kind}")
        seen[row.name] = row
    return tuple(rows)


def list_dependencies(variable: FmuVariable, variables: tuple[FmuVariable, ...],
                      structure: tuple[tuple[str, ...], ...] | None = None,
                      ) -> tuple[tuple[FmuVariable, str], ...]:
    """The knowns (states, inputs) an output or state derivative depends on, with their kinds.

    Parameters
    ----------
    variable : FmuVariable
        An output or a state derivative.
    variables : tuple of FmuVariable
        The whole table.
    structure : tuple of tuple of str, optional
        The model's Jacobian structure (:attr:`panto.fmu_src.spec.ModelSpec.dependencies`):
        rows state derivatives then outputs, entries states then inputs, each ``""`` or an
        FMI ``dependenciesKind``. Without it ``der(q_i) = v_i`` depends on ``v_i`` only
        (``"constant"``) and everything else on every state and input (``"dependent"``).

    Returns
    -------
    tuple of (FmuVariable, str)
        The knowns in value-reference order, each with its ``dependenciesKind``.
    """
    knowns = [v for v in variables if v.kind in ("state", "input")]
    n_states = sum(1 for v in knowns if v.kind == "state")
    row = variable.index if variable.kind == "derivative" else n_states + variable.index
    if structure is None:
        if variable.kind == "derivative" and variable.index < n_states // 2:
            kinds = ["constant" if k.kind == "state" and k.index == n_states // 2 + variable.index
                     else "" for k in knowns]
        else:
            kinds = ["dependent"] * len(knowns)
    else:
        kinds = [structure[row][k.index if k.kind == "state" else n_states + k.index]
                 for k in knowns]
    return tuple((known, kind) for known, kind in zip(knowns, kinds) if kind)


#: Codes of the dependency kinds in the C table (``CoreDependencyKind`` in ``fmu_core.h``).
DEPENDENCY_CODES = {"": 0, "constant": 1, "fixed": 2, "tunable": 3, "discrete": 4, "dependent": 5}


def dependency_table_lines(spec: ModelSpec, variables: tuple[FmuVariable, ...]) -> list[str]:
    """C lines of ``MODEL_DEPENDENCIES``: the kind of each unknown's dependency on each known.

    Row ``i`` is state derivative ``i`` (``i < NX``) or output ``i - NX``; column ``k`` is state
    ``k`` or input ``k - NX``; the codes are :data:`DEPENDENCY_CODES`. The runtime answers
    ``fmi3GetVariableDependencies`` from it, so it always agrees with ``<ModelStructure>``.

    Parameters
    ----------
    spec : ModelSpec
    variables : tuple of FmuVariable

    Returns
    -------
    list of str
    """
    knowns = [v for v in variables if v.kind in ("state", "input")]
    unknowns = ([v for v in variables if v.kind == "derivative"]
                + [v for v in variables if v.kind == "output"])
    lines = ["/* dependency kinds: rows der(x) then y, columns x then u (0: none) */",
             f"static const unsigned char MODEL_DEPENDENCIES[{max(1, len(unknowns) * len(knowns))}]"
             " = {"]
    for unknown in unknowns:
        kinds = dict((known.value_reference, kind) for known, kind in
                     list_dependencies(unknown, variables, spec.dependencies))
        codes = [str(DEPENDENCY_CODES[kinds.get(k.value_reference, "")]) for k in knowns]
        lines.append(f"    {', '.join(codes)}, /* {unknown.name} */")
    lines.append("};")
    return lines
