"""The physical pantograph model as identification structures (thesis sections 2.5, 4.1.3, 4.5).

Two structures share the parameters of thesis Table 4.1 (13 free by default: the masses ``m1``-``m4``,
``m_c``, the dampers ``c1``, ``c2``, ``c3``, ``c_c``, the stiffnesses ``k``, ``k_c``, ``k_ph`` and the
bellow gain ``k_p``); every other model parameter (geometry, ``g``) keeps its value from
:func:`panto.fmu_src.models.default_parameters`, or the one given in ``fixed``.

:class:`PhysicalLinear` (``"physical-linear"``) does what the thesis did for every candidate of its
genetic algorithm (section 4.1.3, steps 1-3):

1. the static equilibrium ``r(q, 0, u0) = 0`` at the operating point ``u0`` (mean or first input
   sample of the data) by Newton's method from the nominal equilibrium;
2. the exact linearisation about it (eqs. 2.27-2.30). At an equilibrium the acceleration is zero,
   so ``A = [[0, I], [M^-1 dr/dq, M^-1 dr/dv]]``, ``B = [[0], [M^-1 dr/du]]``;
3. exact discretisation (``hold="foh"``: inputs linear between samples, the FMUs' convention;
   ``"zoh"``: held) and the free run of the deviations from the linear equilibrium at the first
   input sample; the outputs are ``y0 + C dx + D du``.

For speed the functions of steps 1-2 are compiled here from the symbolic model with the
velocities set to zero before differentiating (``dr/dq`` at ``v = 0`` has about 1 500 operations
instead of 350 000), once per process (about a second), so a candidate costs about a millisecond
for a minute of data at 50 Hz.

:class:`PhysicalNonlinear` (``"physical"``) runs the Pantograph FMU (co-simulation, its own
solver; started in static equilibrium at the first input sample) through one reused
:class:`panto.build_fmu.simulate.FmuSimulator` per process; besides Table 4.1 it can free the extension
parameters ``T_f``, ``kappa_p`` and ``k_c3`` (hinge friction, angle-dependent bellow, stiffening
head suspension). One run costs about 0.09 s of CPU for a minute of data at 50 Hz, nearly all of
it the FMU's own integration (Model Exchange with fmpy's CVODE is about 7 times slower), and the
FMU gives no parameter sensitivities: a finite-difference Jacobian costs one run per free
parameter. Its least-squares fits therefore reuse each Jacobian with Broyden's rank-1 updates
(``broyden_updates``; :func:`panto.identification.estimation.least_squares.fit_least_squares`):
on the benchmark of ``benchmarks/identification_speed.md`` (13 parameters) the fit ends at the
same cost in about a third of the runs.

Both take the measurement's latency into account with the parameter ``eta_delay`` [s], how late
the measured slider height is: ``eta_measured(t) = eta(t - eta_delay)``, so the model receives
``eta_measured(t + eta_delay)`` (a band-limited fractional shift of the input samples,
:func:`panto.identification.data.datasets.delay_signal`, before the simulation; the last samples read the held
end value). The rig's drive reports the position about 5 ms late (:mod:`panto.identification.data.datasets`);
a negative value would mean the measurement leads. It is fixed (default 0, or the ``eta_delay``
option, or ``fixed={"eta_delay": ...}``) unless named among the free parameters, and it does not
go to the model's parameter file.
"""
from __future__ import annotations

import math
import weakref
from functools import lru_cache
from typing import Any, Mapping, NamedTuple, Sequence

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure)
from panto.identification.data.datasets import delay_signal
from panto.identification.structures.linearisation import (INDEX as _INDEX, discretise, linearise,
                                          default_parameter_set as _default_parameter_set,
                                          parameter_defaults as _parameter_defaults, propagate,
                                          solve_equilibrium, static_functions)

#: The 13 parameters of thesis Table 4.1 (with k_p from the text below it).
TABLE_4_1 = ("m1", "m2", "m3", "m4", "m_c", "c1", "c2", "c3", "c_c", "k", "k_c", "k_ph", "k_p")
#: Extension parameters the nonlinear structure may free (diagnosis candidates).
EXTENSIONS = ("T_f", "kappa_p", "k_c3")
#: Input delay of the measured eta [s] (module notes); a structure parameter, not a model one.
DELAY = "eta_delay"
#: Carbon-contact stiffness of EN 50318 [N/m] (thesis section 4.5).
EN50318_CONTACT_STIFFNESS = 50000.0
INPUT_NAMES = ("eta", "p")
OUTPUT_NAMES = ("y_cb", "xi", "F_c")
DEFAULT_OUTPUTS = ("F_c", "y_cb")

#: Identification ranges: physically plausible for the thesis' pantograph (section 4.1.3:
#: "neither negative nor unrealistically large masses"); all positive where the model needs it.
BOUNDS: dict[str, tuple[float, float]] = {
    "m1": (1.0, 100.0), "m2": (0.1, 50.0), "m3": (0.1, 50.0), "m4": (1.0, 100.0),
    "m_c": (0.5, 50.0),
    "c1": (1.0, 1e5), "c2": (1.0, 1e6), "c3": (1.0, 1e5), "c_c": (0.1, 1e4),
    "k": (1e3, 1e9), "k_c": (100.0, 1e6), "k_ph": (100.0, 1e7), "k_p": (10.0, 5000.0),
    "T_f": (0.0, 500.0), "kappa_p": (-5.0, 5.0), "k_c3": (-1e9, 1e9),
    DELAY: (-0.02, 0.1),
}


# --- structures -----------------------------------------------------------------------------

class _PhysicalBase(ModelStructure):
    """What both physical structures share: parameters, bounds, the value checks."""

    input_names = INPUT_NAMES
    #: Every output the structure can simulate (``output_names`` picks the fitted ones).
    simulable_outputs = OUTPUT_NAMES
    extensions: tuple[str, ...] = ()

    def __init__(self, *, outputs: Sequence[str] = DEFAULT_OUTPUTS,
                 fixed: Mapping[str, float] | None = None,
                 contact_stiffness: float | None = None, eta_delay: float = 0.0) -> None:
        unknown = [o for o in outputs if o not in OUTPUT_NAMES]
        if unknown or not outputs:
            raise IdentificationError(f"{self.name}: outputs {list(outputs)}: choose from "
                                      f"{OUTPUT_NAMES}")
        fixed = dict(fixed or {})
        delay = float(fixed.pop(DELAY, eta_delay))
        low, high = BOUNDS[DELAY]
        if not low <= delay <= high:
            raise IdentificationError(f"{self.name}: eta_delay = {delay!r} s lies outside "
                                      f"[{low:g}, {high:g}] s")
        self.eta_delay = delay
        if contact_stiffness is not None:
            fixed["k_ph"] = float(contact_stiffness)
        names = _parameter_defaults()[0]
        bad = sorted(set(fixed) - set(names))
        if bad:
            raise IdentificationError(f"{self.name}: unknown model parameter(s) {bad}; the "
                                      f"pantograph has {list(names)}")
        from panto.fmu_src.parameters import ParameterError

        try:
            _default_parameter_set().with_values(fixed)
        except ParameterError as error:
            raise IdentificationError(f"{self.name}: fixed values: {error}") from None
        self.output_names = tuple(outputs)
        self.fixed = {k: float(v) for k, v in fixed.items()}
        self.parameter_names = TABLE_4_1 + self.extensions + (DELAY,)

    def default_free(self) -> tuple[str, ...]:
        """Table 4.1's 13 parameters, less those given in ``fixed``."""
        return tuple(n for n in TABLE_4_1 if n not in self.fixed)

    def nominal(self) -> dict[str, float]:
        """Table 4.1 (the model defaults), overridden by ``fixed``; ``eta_delay``."""
        names, vector = _parameter_defaults()
        values = dict(zip(names, vector.tolist())) | self.fixed | {DELAY: self.eta_delay}
        return {n: values[n] for n in self.parameter_names}

    def bounds(self) -> dict[str, tuple[float, float]]:
        """:data:`BOUNDS` for :attr:`parameter_names`."""
        return {n: BOUNDS[n] for n in self.parameter_names}

    def units(self) -> dict[str, str]:
        """Unit of every parameter: the Pantograph parameter set's (thesis Table 4.1); ``eta_delay``
        in s."""
        specs = _default_parameter_set()
        return {n: "s" if n == DELAY else specs.spec(n).unit for n in self.parameter_names}

    def parameter_vector(self, parameters: Mapping[str, float]) -> np.ndarray:
        """The model's full parameter vector: defaults, ``fixed``, then `parameters` (whose
        ``eta_delay``, not a model parameter, is ignored here)."""
        parameters = {k: v for k, v in parameters.items() if k != DELAY}
        unknown = sorted(set(parameters) - set(self.parameter_names))
        if unknown:
            raise IdentificationError(f"{self.name}: unknown parameter(s) {unknown}; known: "
                                      f"{list(self.parameter_names)}")
        names, vector = _parameter_defaults()
        vector = vector.copy()
        for name, value in (self.fixed | {k: float(v) for k, v in parameters.items()}).items():
            vector[_INDEX[name]] = value
        if not np.all(np.isfinite(vector)):
            raise IdentificationError(f"{self.name}: non-finite parameter values {dict(parameters)}")
        positive = [n for n in TABLE_4_1 if vector[_INDEX[n]] <= 0.0 and n not in ("c1", "c2", "c3", "c_c")]
        negative = [n for n in ("c1", "c2", "c3", "c_c", "T_f") if vector[_INDEX[n]] < 0.0]
        if positive or negative:
            raise IdentificationError(f"{self.name}: inadmissible values "
                                      f"{ {n: vector[_INDEX[n]] for n in positive + negative} }")
        return vector

    def _rows(self) -> list[int]:
        return [OUTPUT_NAMES.index(o) for o in self.output_names]

    def model_inputs(self, parameters: Mapping[str, float], data: IdentificationData
                     ) -> np.ndarray:
        """Columns ``(eta, p)`` the model receives: eta advanced by ``eta_delay`` (module notes)."""
        u = np.column_stack([data.input(n) for n in INPUT_NAMES])
        delay = float(parameters.get(DELAY, self.eta_delay))
        if not math.isfinite(delay):
            raise IdentificationError(f"{self.name}: eta_delay = {delay!r}")
        if delay != 0.0:
            u[:, 0] = delay_signal(u[:, 0], -delay / data.sample_period)
        return u


class PhysicalLinear(_PhysicalBase):
    """The physical model linearised about its equilibrium for every candidate (thesis 4.1.3).

    Parameters
    ----------
    outputs : sequence of str
        Simulated outputs, any of ``("y_cb", "xi", "F_c")``.
    fixed : mapping, optional
        Values of any model parameters held fixed (geometry, ``k_ph``, ...).
    contact_stiffness : float, optional
        Fix ``k_ph`` (e.g. :data:`EN50318_CONTACT_STIFFNESS`, section 4.5).
    operating_point : {"mean", "first"}
        Inputs linearised about: their mean over the data, or the first sample.
    hold : {"foh", "zoh"}
        Inputs linear between samples (default, as the FMUs) or held.
    eta_delay : float
        How late the measured eta is [s] (module notes): the nominal value of the parameter
        ``eta_delay`` (fixed unless freed).
    """

    name = "physical-linear"
    extensions = ("kappa_p", "k_c3")
    difference_step = 1e-6

    @property
    def input_refinement(self) -> bool:
        """Continuous time, exact discretisation: refinable when inputs are linear between
        samples (``hold="foh"``)."""
        return self.hold == "foh"

    def __init__(self, *, outputs: Sequence[str] = DEFAULT_OUTPUTS,
                 fixed: Mapping[str, float] | None = None, contact_stiffness: float | None = None,
                 operating_point: str = "mean", hold: str = "foh", eta_delay: float = 0.0) -> None:
        super().__init__(outputs=outputs, fixed=fixed, contact_stiffness=contact_stiffness,
                         eta_delay=eta_delay)
        if operating_point not in ("mean", "first"):
            raise IdentificationError(f"operating_point {operating_point!r}: 'mean' or 'first'")
        if hold not in ("foh", "zoh"):
            raise IdentificationError(f"hold {hold!r}: choose 'foh' or 'zoh'")
        self.operating_point = operating_point
        self.hold = hold

    def linear_model(self, parameters: Mapping[str, float], u0: Sequence[float]):
        """``(A, B, C, D, x0, y0)`` for all outputs about the equilibrium at `u0`."""
        p = self.parameter_vector(parameters)
        return linearise(p, [float(u0[0]), float(u0[1])], _nominal_start(float(u0[0]), float(u0[1])))

    def linear_system(self, parameters: Mapping[str, float], data: IdentificationData
                      ) -> tuple[np.ndarray, ...]:
        """Continuous ``(A, B, C, D)`` from `data`'s inputs to `data`'s outputs (their units),
        linearised about the operating point of `data` (``operating_point``). The input delay
        ``eta_delay`` is not part of it."""
        a, b, c, d, _, _ = self.linear_model(parameters, self._operating_point(parameters, data))
        inputs, rows, both = _signals(self.name, data.input_names, data.output_names)
        return a, b[:, inputs], c[rows], d[both]

    def _operating_point(self, parameters: Mapping[str, float], data: IdentificationData
                         ) -> np.ndarray:
        """The inputs ``(eta, p)`` linearised about (``operating_point``) of
        :meth:`model_inputs`, remembered per record, input delay and rule
        (:data:`_OPERATING_POINTS`, the last :data:`_OPERATING_POINTS_KEPT` per record: a free
        delay gives a new one at every evaluation): they depend on no other parameter, and the
        record's arrays are read-only."""
        key = (float(parameters.get(DELAY, self.eta_delay)), self.operating_point)
        remembered = _OPERATING_POINTS.setdefault(data, {})
        if key not in remembered:
            u = self.model_inputs(parameters, data)
            u0 = u.mean(axis=0) if self.operating_point == "mean" else u[0].copy()
            u0.setflags(write=False)
            while len(remembered) >= _OPERATING_POINTS_KEPT:
                remembered.pop(next(iter(remembered)))
            remembered[key] = u0
        return remembered[key]

    def deviation_model(self, parameters: Mapping[str, float], data: IdentificationData
                        ) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, y0, du, x_start)``: the linearisation about the operating point (all
        outputs), the inputs' deviations ``du`` from it and the state in equilibrium with the
        first input sample."""
        u = self.model_inputs(parameters, data)
        u0 = u.mean(axis=0) if self.operating_point == "mean" else u[0]
        a, b, c, d, _, y0 = self.linear_model(parameters, u0)
        du = u - u0
        try:
            x_start = -np.linalg.solve(a, b @ du[0])
        except (np.linalg.LinAlgError, ValueError) as error:
            raise IdentificationError(f"{self.name}: singular linearisation ({error})") from None
        return a, b, c, d, y0, du, x_start

    def discrete_model(self, parameters: Mapping[str, float], data: IdentificationData
                       ) -> DiscreteLinear:
        """The linearisation about the operating point, discretised on `data`'s sample period
        (``x[k+1] = Phi x[k] + drive[k]``), its start in equilibrium with the first input and the
        output map of the simulated outputs (module notes)."""
        a, b, c, d, y0, du, x_start = self.deviation_model(parameters, data)
        phi, gamma0, gamma1 = discretise(a, b, data.sample_period, self.hold)
        drive = du[:-1] @ gamma0.T + np.diff(du, axis=0) @ gamma1.T
        rows = self._rows()
        return DiscreteLinear(phi, gamma0, drive, x_start, du, c[rows], d[rows], y0[rows])

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Free run of the linearised model on `data`'s inputs (module notes)."""
        model = self.discrete_model(parameters, data)
        with np.errstate(over="ignore", invalid="ignore"):  # an unstable candidate: refused below
            states = propagate(model.phi, model.drive, model.x_start)
        return model.outputs(states, self.name)


class DiscreteLinear(NamedTuple):
    """A discretised linearisation of :class:`PhysicalLinear` on one record."""

    phi: np.ndarray
    gamma0: np.ndarray
    drive: np.ndarray
    x_start: np.ndarray
    du: np.ndarray
    c: np.ndarray
    d: np.ndarray
    y0: np.ndarray

    def outputs(self, states: np.ndarray, name: str) -> np.ndarray:
        """``y0 + C x + D du``; refuses an unstable or diverged run."""
        with np.errstate(over="ignore", invalid="ignore"):
            y = self.y0 + states @ self.c.T + self.du @ self.d.T
        if not np.all(np.isfinite(y)) or np.max(np.abs(np.linalg.eigvals(self.phi))) > 1.0 + 1e-9:
            raise IdentificationError(f"{name}: unstable linearisation")
        return y


@lru_cache(maxsize=16)
def _signals(name: str, input_names: tuple[str, ...], output_names: tuple[str, ...]
             ) -> tuple[list[int], list[int], tuple[np.ndarray, np.ndarray]]:
    """The model's input columns and output rows of a record's signals and ``np.ix_`` of both
    (:meth:`PhysicalLinear.linear_system`); raises for a signal the model lacks."""
    missing = [n for n in (*input_names, *output_names) if n not in INPUT_NAMES + OUTPUT_NAMES]
    if missing:
        raise IdentificationError(f"{name}: no signal(s) {missing}")
    inputs = [INPUT_NAMES.index(n) for n in input_names]
    rows = [OUTPUT_NAMES.index(n) for n in output_names]
    return inputs, rows, np.ix_(rows, inputs)


#: The operating points of :meth:`PhysicalLinear.linear_system` by record (as long as it lives),
#: then by input delay and rule. Keyed by the record itself: :class:`IdentificationData` hashes by
#: identity (``eq=False``) and makes its arrays read-only (a record built on a view of an array
#: its caller then writes to would leave a stale operating point here).
_OPERATING_POINTS: weakref.WeakKeyDictionary[IdentificationData, dict[tuple, np.ndarray]] = \
    weakref.WeakKeyDictionary()
#: Operating points kept per record (input delays, rules).
_OPERATING_POINTS_KEPT = 16


@lru_cache(maxsize=64)
def _nominal_start(eta: float, p: float) -> np.ndarray:
    """Equilibrium coordinates of the default model at (eta, p): Newton's starting point."""
    return solve_equilibrium(_parameter_defaults()[1], [eta, p])


class PhysicalNonlinear(_PhysicalBase):
    """The nonlinear physical model: the Pantograph FMU in the loop (co-simulation).

    Parameters
    ----------
    outputs, fixed, contact_stiffness
        As :class:`PhysicalLinear`.
    fmu_path : str, optional
        A Pantograph FMU (default: :func:`panto.build_fmu.project.project_fmu`, built if needed).
    solver_tolerance : float, optional
        The FMU's solver tolerance (default: the FMU's).
    eta_delay : float
        As :class:`PhysicalLinear`.

    Notes
    -----
    The FMU starts in static equilibrium at the first input sample and receives the inputs as
    piecewise linear (their mean over each step, see :mod:`panto.build_fmu.simulate`). The simulator is
    opened lazily, once per process, and never pickled.
    """

    name = "physical"
    extensions = EXTENSIONS
    #: Finite-difference step in the relative parameters: above the FMU solver's error.
    difference_step = 1e-4
    #: Iterations a finite-difference Jacobian is reused with Broyden updates
    #: (:func:`panto.identification.estimation.least_squares.fit_least_squares`, ``broyden``): a
    #: fresh one costs a run of the FMU per free parameter, an updated step one or two.
    broyden_updates = 10

    def __init__(self, *, outputs: Sequence[str] = DEFAULT_OUTPUTS,
                 fixed: Mapping[str, float] | None = None, contact_stiffness: float | None = None,
                 fmu_path: str | None = None, solver_tolerance: float | None = None,
                 eta_delay: float = 0.0) -> None:
        super().__init__(outputs=outputs, fixed=fixed, contact_stiffness=contact_stiffness,
                         eta_delay=eta_delay)
        if fmu_path is None:
            from panto.build_fmu.project import project_fmu

            fmu_path = str(project_fmu("Pantograph"))
        self.fmu_path = str(fmu_path)
        self.solver_tolerance = solver_tolerance

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        """Free run of the FMU on `data`'s inputs; FMU failures become IdentificationError."""
        from panto.build_fmu.simulate import SimulationError

        vector = self.parameter_vector(parameters)
        values = {n: float(vector[_INDEX[n]]) for n in self.parameter_names
                  if n != DELAY} | self.fixed
        simulator = _simulator(self.fmu_path)
        u = self.model_inputs(parameters, data)
        try:
            response = simulator.simulate(
                data.time, {n: u[:, i] for i, n in enumerate(INPUT_NAMES)}, parameters=values,
                solver_tolerance=self.solver_tolerance)
        except SimulationError as error:
            raise IdentificationError(f"{self.name}: the FMU failed for {dict(parameters)}: "
                                      f"{str(error).splitlines()[0]}") from None
        y = np.column_stack([response[o] for o in self.output_names])
        if not np.all(np.isfinite(y)):
            raise IdentificationError(f"{self.name}: non-finite outputs for {dict(parameters)}")
        return y


_SIMULATORS: dict[str, Any] = {}


def _simulator(path: str):
    """One FmuSimulator per FMU path and process (opened at first use)."""
    if path not in _SIMULATORS:
        from panto.build_fmu.simulate import FmuSimulator

        _SIMULATORS[path] = FmuSimulator(path, interface="CS")
    return _SIMULATORS[path]


# --- identifiers --------------------------------------------------------------------------

def _identify(structure_type: type, data: IdentificationData, *, executor=None, progress=None,
              free: Sequence[str] | None = None, fixed: Mapping[str, float] | None = None,
              method: str = "lm", outputs: Sequence[str] | None = None,
              structure_options: Mapping[str, Any] | None = None,
              **options: Any) -> IdentificationResult:
    """Fit a physical structure: ``method="lm"`` (:func:`fit_least_squares`) or ``"nsga2"``."""
    outputs = tuple(outputs or [o for o in DEFAULT_OUTPUTS if o in data.output_names])
    structure = structure_type(outputs=outputs, fixed=fixed, **dict(structure_options or {}))
    free = tuple(free) if free is not None else structure.default_free()
    clash = sorted(set(free) & set(structure.fixed))
    if clash:
        raise IdentificationError(f"parameter(s) {clash} are both free and fixed")
    data = data.select_outputs(outputs)
    adequacy = bool(options.pop("adequacy", False))
    if method == "lm":
        from panto.identification.structures.adequacy import fit_checked

        return fit_checked(structure, data, structure.nominal(), adequacy, progress=progress,
                           free=free, executor=executor, **options)
    if method == "nsga2":
        return _identify_pareto(structure, data, free, executor, progress, options)
    raise IdentificationError(f"unknown method {method!r}: 'lm' or 'nsga2'")


def _identify_pareto(structure, data, free, executor, progress, options) -> IdentificationResult:
    try:
        from panto.identification.estimation.genetic import fit_pareto
    except ImportError as error:
        raise IdentificationError(f"method 'nsga2' is not available ({error})") from None
    pick = options.pop("pick", "knee")
    polish = options.pop("polish", True)
    pareto = fit_pareto(structure, data, free=free, executor=executor, progress=progress,
                        objectives=tuple(o for o in ("y_cb", "F_c") if o in data.output_names),
                        **options)
    chosen = pareto.pick(rule=pick)
    return pareto.polish(chosen, data, executor=executor, progress=progress) if polish else chosen


def identify_linear(data: IdentificationData, **options: Any) -> IdentificationResult:
    """Identify :class:`PhysicalLinear` (options: free, fixed, method, outputs, structure_options,
    and those of :func:`panto.identification.estimation.least_squares.fit_least_squares`;
    ``global_fit``: :func:`panto.identification.estimation.global_fit.fit_global`'s options;
    ``adequacy=True``: :func:`panto.identification.structures.adequacy.with_adequacy`)."""
    return _identify(PhysicalLinear, data, **options)


def identify_nonlinear(data: IdentificationData, **options: Any) -> IdentificationResult:
    """Identify :class:`PhysicalNonlinear` (the FMU in the loop; options as :func:`identify_linear`)."""
    return _identify(PhysicalNonlinear, data, **options)


def linear_from_data(data: IdentificationData, **options: Any) -> PhysicalLinear:
    """The nominal :class:`PhysicalLinear` on the outputs of `data` (options: its constructor's)."""
    return PhysicalLinear(outputs=data.output_names, **options)


def nonlinear_from_data(data: IdentificationData, **options: Any) -> PhysicalNonlinear:
    """The nominal :class:`PhysicalNonlinear` on the outputs of `data` (options: its constructor's)."""
    return PhysicalNonlinear(outputs=data.output_names, **options)

__all__ = ["PhysicalLinear", "PhysicalNonlinear", "TABLE_4_1", "EXTENSIONS", "DELAY", "BOUNDS",
           "EN50318_CONTACT_STIFFNESS", "identify_linear", "identify_nonlinear", "linear_from_data",
           "nonlinear_from_data", "linearise",
           "solve_equilibrium", "static_functions"]
