"""What a model hands to the FMU builder: its variables, parameters and generated C code.

A :class:`ModelSpec` is the single contract between the symbolic models of :mod:`fmu_src` and
the packaging in :mod:`build_fmu`. The generated C code implements
``fmu_src/runtime/model_interface.h``; the hand-written runtime in ``fmu_src/runtime`` turns it into
FMI 2.0 and FMI 3.0 functions (Model Exchange and Co-Simulation).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

RUNTIME_DIR = Path(__file__).parent / "runtime"


@dataclass(frozen=True)
class Variable:
    """A named signal of a model (coordinate, velocity, input or output).

    Parameters
    ----------
    name : str
        FMI variable name, e.g. ``"phi1"`` or ``"F_c"``.
    unit : str
        Unit in the project's notation: products with ``.``, powers as digits, one ``/``
        (``"m"``, ``"rad/s"``, ``"N.m.s/rad"``, ``"kg.m2"``, ``"1"`` for dimensionless).
    description : str
        One line a user of an FMI tool reads.
    start : float
        Start value (inputs: the value used for the initial equilibrium; states: the default
        initial value when the FMU is told not to start in equilibrium).
    minimum, maximum : float
        Admissible range in ``unit`` (inputs: values outside are refused by the FMU's setters;
        infinite: no bound).
    nominal : float or None
        Typical magnitude in ``unit`` (states: the FMI ``nominal`` that scales an importer's
        absolute tolerance; ``None``: 1).
    """

    name: str
    unit: str
    description: str
    start: float = 0.0
    minimum: float = float("-inf")
    maximum: float = float("inf")
    nominal: float | None = None


@dataclass(frozen=True)
class ParameterSpec:
    """A tunable parameter with its default value, unit, admissible range and provenance.

    ``minimum``/``maximum`` are the physically admissible range (values outside are refused);
    ``boolean`` parameters are stored as 0.0/1.0 in the parameter vector and exposed as FMI
    Booleans.
    """

    name: str
    value: float
    unit: str
    description: str
    minimum: float = float("-inf")
    maximum: float = float("inf")
    provenance: str = ""
    boolean: bool = False


@dataclass(frozen=True)
class ModelSpec:
    """Everything the FMU builder needs to know about one model.

    The state vector is ``[coordinates..., velocities...]``; ``velocities[i]`` is the time
    derivative of ``coordinates[i]``. ``c_code`` is a complete C translation unit implementing
    ``model_interface.h`` with the variables in exactly this order.

    ``dependencies`` is the structure of the Jacobian of ``[dx/dt; y]`` with respect to
    ``[x; u]``: one row per state derivative then per output, one entry per state then per
    input, each ``""`` (no dependency) or an FMI ``dependenciesKind`` (``"constant"``,
    ``"tunable"``, ``"dependent"``); ``None`` declares every output and acceleration dependent
    on every state and input. ``event_indicators`` names the indicators that ``c_code``
    computes in ``model_event_indicators`` (see ``runtime/model_interface.h``); they are
    offered to Model Exchange importers unless the spec is linearised.
    """

    identifier: str
    description: str
    coordinates: tuple[Variable, ...]
    velocities: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    parameters: tuple[ParameterSpec, ...]
    c_code: str
    linearised: bool = False
    extra: dict = field(default_factory=dict, compare=False)
    dependencies: tuple[tuple[str, ...], ...] | None = None
    event_indicators: tuple[Variable, ...] = ()

    @property
    def states(self) -> tuple[Variable, ...]:
        """Coordinates followed by velocities (the FMI continuous states)."""
        return self.coordinates + self.velocities

    @property
    def active_event_indicators(self) -> tuple[Variable, ...]:
        """The event indicators the FMU declares (none for a linearised model: no switching)."""
        return () if self.linearised else self.event_indicators
