"""D-optimal inputs for the pantograph rig (thesis section 5.5, carried beyond it: both rig inputs).

Both rig inputs are designed at once for a chosen structure
(:class:`panto.identification.design.pantograph_sensitivity.LinearisedPantograph`): the linear-motor position
(model input :math:`\\eta = \\eta_0 + x_\\mathrm{motor}`) and the bellow pressure *demand*, which
reaches the model through the pressure loop's lag. The parametrisation is that of an APRBS with
designed levels (thesis 4.2 uses APRBS for training): levels held for ``motor_hold`` /
``pressure_hold`` seconds, which the GA chooses. The rig's limits are met by construction
(:func:`build_inputs`), never by penalty:

* motor amplitude :math:`x_\\min \\le x \\le x_\\max` (the profile limits, :math:`\\pm 0.13` m);
* motor speed :math:`|\\Delta x| \\le v_\\max T`: the level sequence is followed by sequential
  clipping of the step, so the command never trips the rig's 5 mm/4 ms limiter and stays below
  the speed at which :func:`panto.rig.conditioning.following_error_bound` reaches the drive's
  following-error warning
  (:meth:`~panto.identification.design.constraints.RigInputConstraints.from_rig`);
* motor acceleration :math:`|\\Delta^2 x| \\le a_\\max T^2`: the rate-limited sequence is averaged
  over :math:`L = \\lceil 2 v_\\max / (a_\\max T) \\rceil` samples. A moving average keeps the
  amplitude and speed bounds (it is a convex combination) and changes the speed by at most
  :math:`2 v_\\max / L` per sample;
* pressure demand within :math:`[p_\\min, p_\\max]`; the measured pressure, a first-order lag of
  it, stays inside too;
* contact: the predicted contact force stays above ``minimum_contact_force`` (the virtual and the
  real rig lose contact otherwise; thesis 3.1), a constraint of the GA (feasibility first).

:func:`design_pantograph_experiment` runs the GA (:class:`pymoo.algorithms.soo.nonconvex.ga.GA`,
a whole population scored in one vectorised call) and compares the Cramer-Rao covariance
(eq. 5.1) with that of the conventional input: the APRBS training profile of equal length played
through the rig's conditioning chain
(:func:`~panto.identification.design.constraints.conventional_inputs`).

The criterion is evaluated on the Fisher information of the *relative* parameters
:math:`\\theta_i / \\theta_{i,0}` (A: sum of relative variances; D: unchanged up to a constant;
E: the worst relative direction); covariances are reported in physical units.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from pymoo.algorithms.soo.nonconvex.ga import GA
from pymoo.core.problem import Problem
from pymoo.optimize import minimize

from panto.identification.design.constraints import RigInputConstraints, conventional_inputs
from panto.identification.design.fisher import CRITERIA, cramer_rao_covariance, criterion_cost, criterion_value
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

Progress = Callable[[str], None]


# --- the inputs ---------------------------------------------------------------------------


def level_counts(constraints: RigInputConstraints, n_samples: int) -> tuple[int, int]:
    """Number of motor and pressure levels for an experiment of `n_samples` samples."""
    hold_motor, hold_pressure = constraints.hold_samples()
    return math.ceil((n_samples - 1) / hold_motor), math.ceil((n_samples - 1) / hold_pressure)


def _rate_limited(levels: np.ndarray, hold: int, n_samples: int, step: float) -> np.ndarray:
    """Follow held levels from 0 (sample 0 at rest) with at most `step` per sample."""
    out = np.zeros((*levels.shape[:-1], n_samples))
    current = np.zeros(levels.shape[:-1])
    ramp = step * np.arange(1, hold + 1)
    for j in range(levels.shape[-1]):
        first, stop = 1 + j * hold, min(1 + (j + 1) * hold, n_samples)
        if first >= n_samples:
            break
        change = (levels[..., j] - current)[..., None]
        segment = current[..., None] + np.clip(change, -ramp, ramp)[..., :stop - first]
        out[..., first:stop] = segment
        current = segment[..., -1]
    return out


def _moving_average(values: np.ndarray, length: int) -> np.ndarray:
    """Mean over the last `length` samples, the samples before the start taken as 0 (rest)."""
    if length <= 1:
        return values
    cumulative = np.cumsum(values, axis=-1)
    shifted = np.concatenate([np.zeros((*values.shape[:-1], length)), cumulative], axis=-1)
    return (cumulative - shifted[..., :values.shape[-1]]) / length


def build_inputs(motor_levels: np.ndarray, pressure_levels: np.ndarray,
                 constraints: RigInputConstraints, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Motor positions [m] and pressure demands [bar] ``(..., n_samples)`` from levels.

    The motor follows its levels (clipped into the range) at :math:`v_\\max`, then the moving
    average of :attr:`RigInputConstraints.smoothing_samples` bounds the acceleration (module
    notes); the pressure demand holds its levels. Sample 0 is the rest point (motor 0, the start
    pressure), so every limit holds by construction.
    """
    c = constraints
    hold_motor, hold_pressure = c.hold_samples()
    levels = np.clip(np.asarray(motor_levels, float), c.motor_min, c.motor_max)
    # the average of L samples of a signal moving v T per sample moves v T per sample
    motor = _moving_average(_rate_limited(levels, hold_motor, n_samples,
                                          c.motor_speed * c.sample_period), c.smoothing_samples)
    pressure = np.clip(np.asarray(pressure_levels, float), c.pressure_min, c.pressure_max)
    demand = np.repeat(pressure, hold_pressure, axis=-1)[..., :n_samples - 1]
    demand = np.concatenate([np.full((*demand.shape[:-1], 1), c.pressure_start), demand], axis=-1)
    return motor, demand


def model_inputs(motor: np.ndarray, demand: np.ndarray,
                 constraints: RigInputConstraints) -> np.ndarray:
    """Absolute model inputs ``(..., N, 2)``: :math:`(\\eta_0 + x, p^*)`."""
    return np.stack([constraints.motor_zero_height + np.asarray(motor), np.asarray(demand)], axis=-1)


# --- the design ------------------------------------------------------------------------------


@dataclass(frozen=True)
class PantographDesign:
    """A designed experiment for the rig, with its promise and the conventional input's.

    Parameters
    ----------
    structure : str
    parameter_names : tuple of str
        The free parameters designed for.
    parameters : mapping
        All parameter values the design is computed at.
    criterion : str
    time : ndarray, shape (N,)
    motor_position, pressure_demand, pressure : ndarray, shape (N,)
        Designed motor position [m] (about mid-stroke), pressure demand and predicted measured
        pressure [bar].
    conventional_motor_position, conventional_pressure_demand : ndarray, shape (N,)
    outputs, conventional_outputs : ndarray, shape (N, n_outputs)
        Predicted (noise-free) outputs.
    output_names : tuple of str
    noise_variance : ndarray
        :math:`\\sigma^2` per output.
    fisher, covariance, conventional_fisher, conventional_covariance : ndarray
        Fisher information (eq. 5.6) and Cramer-Rao covariance (eq. 5.1), physical units.
    value, conventional_value : float
        Criterion of the relative-parameter Fisher information (module notes).
    constraints : RigInputConstraints
    history : ndarray
        Best cost per generation.
    n_evaluations : int
    wall_time : float
    message : str
    """

    structure: str
    parameter_names: tuple[str, ...]
    parameters: Mapping[str, float]
    criterion: str
    time: np.ndarray
    motor_position: np.ndarray
    pressure_demand: np.ndarray
    pressure: np.ndarray
    conventional_motor_position: np.ndarray
    conventional_pressure_demand: np.ndarray
    outputs: np.ndarray
    conventional_outputs: np.ndarray
    output_names: tuple[str, ...]
    noise_variance: np.ndarray
    fisher: np.ndarray
    covariance: np.ndarray
    conventional_fisher: np.ndarray
    conventional_covariance: np.ndarray
    value: float
    conventional_value: float
    constraints: RigInputConstraints
    history: np.ndarray
    n_evaluations: int
    wall_time: float
    message: str

    @property
    def std(self) -> np.ndarray:
        """Predicted standard deviation per free parameter (designed input)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def conventional_std(self) -> np.ndarray:
        """Predicted standard deviation per free parameter (conventional input)."""
        return np.sqrt(np.diag(self.conventional_covariance))

    def covariance_table(self) -> list[dict[str, float | str]]:
        """Per parameter: value, predicted std (designed, conventional) and their ratio."""
        return [{"parameter": n, "value": float(self.parameters[n]), "std_designed": float(a),
                 "std_conventional": float(b), "ratio_conventional_to_designed": float(b / a)}
                for n, a, b in zip(self.parameter_names, self.std, self.conventional_std)]

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (covariance table, criteria, determinant ratio, timing)."""
        _, logdet = np.linalg.slogdet(self.fisher)
        _, logdet_conventional = np.linalg.slogdet(self.conventional_fisher)
        return {"structure": self.structure, "criterion": self.criterion,
                "free": list(self.parameter_names), "duration_s": float(len(self.time) *
                                                                        self.constraints.sample_period),
                "outputs": list(self.output_names), "noise_variance": self.noise_variance.tolist(),
                "value": self.value, "conventional_value": self.conventional_value,
                "det_ratio_per_parameter": float(np.exp((logdet - logdet_conventional)
                                                        / len(self.parameter_names))),
                "table": self.covariance_table(), "n_evaluations": self.n_evaluations,
                "wall_time_s": self.wall_time, "message": self.message,
                "violations": self.constraints.violations(self.motor_position,
                                                          self.pressure_demand),
                "min_contact_force_N": _min_force(self.outputs, self.output_names)}


def _min_force(outputs: np.ndarray, names: Sequence[str]) -> float | None:
    return float(np.min(outputs[:, list(names).index("F_c")])) if "F_c" in names else None


@dataclass(frozen=True)
class DesignOptions:
    """GA settings: population, generations, seed; the initial population holds binary level
    sequences at amplitude fractions ``amplitudes`` of the ranges and uniform random levels,
    shrunk until the contact constraint holds."""

    population: int = 40
    generations: int = 60
    seed: int = 0
    amplitudes: tuple[float, ...] = (0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0)

    def __post_init__(self) -> None:
        if self.population < 4 or self.generations < 1:
            raise ValueError(f"DesignOptions need population >= 4 and generations >= 1, got {self}")


class LevelProblem(Problem):
    """Variables: motor then pressure levels scaled to [0, 1]; objective: criterion cost;
    constraint: least predicted contact force."""

    def __init__(self, model: LinearisedPantograph, constraints: RigInputConstraints,
                 n_samples: int, criterion: str, noise_variance: np.ndarray) -> None:
        self.counts = level_counts(constraints, n_samples)
        constrained = constraints.minimum_contact_force is not None
        super().__init__(n_var=sum(self.counts), n_obj=1, n_ieq_constr=int(constrained),
                         xl=0.0, xu=1.0)
        self.model, self.constraints, self.n_samples = model, constraints, n_samples
        self.criterion, self.noise_variance = criterion, noise_variance
        self.scale = np.abs(model.theta) + (model.theta == 0)
        self.n_evaluations = 0

    def inputs(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Motor positions and pressure demands of scaled level vectors `x` (:func:`build_inputs`)."""
        c, (n_motor, _) = self.constraints, self.counts
        motor = c.motor_min + x[..., :n_motor] * (c.motor_max - c.motor_min)
        pressure = c.pressure_min + x[..., n_motor:] * (c.pressure_max - c.pressure_min)
        return build_inputs(motor, pressure, c, self.n_samples)

    def scores(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Criterion cost and contact-force violation per row of `x`."""
        u = model_inputs(*self.inputs(x), self.constraints)
        fisher = self.model.fisher(u, self.noise_variance) * np.outer(self.scale, self.scale)
        cost = np.asarray(criterion_cost(fisher + 1e-12 * np.eye(len(self.scale)), self.criterion))
        self.n_evaluations += len(u)
        return np.where(np.isfinite(cost), cost, 1e300), self.contact_violation(u)

    def contact_violation(self, u: np.ndarray) -> np.ndarray | None:
        """Least contact force short of the minimum [N] per candidate (None: unconstrained)."""
        if self.constraints.minimum_contact_force is None:
            return None
        return self.constraints.minimum_contact_force - np.min(
            self.model.simulate(u, ["F_c"])[..., 0], axis=-1)

    def _evaluate(self, x, out, *args, **kwargs):
        cost, force = self.scores(np.atleast_2d(x))
        out["F"] = cost
        if force is not None:
            out["G"] = force


def run_level_ga(problem: Any, options: DesignOptions, callback: Callable[[Any], None]) -> Any:
    """pymoo's GA over the rig's input levels, from :func:`initial_level_population`, as both the
    D-optimal and the discrimination designs run it (`callback` sees every generation)."""
    algorithm = GA(pop_size=options.population,
                   sampling=initial_level_population(problem, options), eliminate_duplicates=False)
    return minimize(problem, algorithm, ("n_gen", options.generations), seed=options.seed,
                    verbose=False, callback=callback)


def initial_level_population(problem: LevelProblem, options: DesignOptions) -> np.ndarray:
    """The GA's first population for `problem`.

    Binary level sequences (motor and pressure at independent amplitude fractions about the
    middle of their ranges) and uniform random levels; each shrunk towards the middle until the
    contact constraint holds (the motor part first; at most ten halvings)."""
    rng = np.random.default_rng(options.seed)
    n_motor = problem.counts[0]
    rows = []
    for index in range(options.population):
        if index % 4 == 3:
            rows.append(rng.uniform(0.0, 1.0, problem.n_var))
            continue
        amplitude = np.where(np.arange(problem.n_var) < n_motor,
                             rng.choice(options.amplitudes), rng.choice(options.amplitudes))
        rows.append(0.5 + amplitude * (rng.integers(0, 2, problem.n_var) - 0.5))
    population = np.array(rows)
    if problem.constraints.minimum_contact_force is None:
        return population
    for attempt in range(10):
        violation = problem.contact_violation(model_inputs(*problem.inputs(population),
                                                           problem.constraints))
        bad = violation > 0
        if not bad.any():
            break
        columns = slice(0, n_motor) if attempt < 5 else slice(None)  # the motor first
        population[bad, columns] = 0.5 + 0.5 * (population[bad, columns] - 0.5)
    return population


def design_pantograph_experiment(model: LinearisedPantograph,
                                 constraints: RigInputConstraints = RigInputConstraints(), *,
                                 criterion: str = "D",
                                 noise_variance: Sequence[float] | None = None,
                                 options: DesignOptions = DesignOptions(),
                                 conventional: tuple[np.ndarray, np.ndarray] | None = None,
                                 progress: Progress | None = None) -> PantographDesign:
    """Design motor position and pressure demand for `model`'s free parameters (section 5.5).

    Parameters
    ----------
    model : LinearisedPantograph
        Structure at its parameter guess; ``model.length`` is the number of samples N.
    constraints : RigInputConstraints
    criterion : {"A", "D", "E"}
    noise_variance : sequence of float, optional
        :math:`\\sigma^2` per output (default: the rig's sensor noise).
    options : DesignOptions
    conventional : (motor, demand), optional
        The input to compare with (default :func:`conventional_inputs`).
    progress : callable, optional
        A line about every tenth of the generations.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    if model.operating_point != constraints.operating_point():
        raise ValueError(f"model operating point {model.operating_point} differs from the "
                         f"constraints' rest point {constraints.operating_point()}")
    began = time.perf_counter()
    n = model.length
    variance = np.asarray(noise_variance if noise_variance is not None
                          else model.noise_variance_default(), float)
    problem = LevelProblem(model, constraints, n, criterion, variance)
    history: list[float] = []
    every = max(1, options.generations // 10)

    def callback(algorithm) -> None:
        history.append(float(algorithm.opt.get("F").min()))
        if progress is not None and (algorithm.n_gen % every == 0 or algorithm.n_gen == 1):
            progress(f"pantograph DoE: generation {algorithm.n_gen}/{options.generations}, "
                     f"best cost {history[-1]:.6g}")

    result = run_level_ga(problem, options, callback)
    if result.X is None:
        raise ValueError("no design met the contact-force constraint; lower "
                         "minimum_contact_force or the amplitude range")
    motor, demand = problem.inputs(np.asarray(result.X, float))
    if conventional is None:
        conventional = conventional_inputs(n, constraints)
    return _design_result(problem, (motor, demand), conventional, np.asarray(history),
                          time.perf_counter() - began,
                          f"GA: {options.generations} generations of {options.population}, "
                          f"{problem.n_var} levels")


def _design_result(problem: LevelProblem, designed: tuple[np.ndarray, np.ndarray],
                   conventional: tuple[np.ndarray, np.ndarray], history: np.ndarray,
                   wall_time: float, message: str) -> PantographDesign:
    """The design and the conventional input, each with its Fisher information, Cramer-Rao
    covariance, criterion value and simulated outputs, for `problem`'s model and constraints."""
    model, constraints = problem.model, problem.constraints
    criterion, variance = problem.criterion, problem.noise_variance
    n_evaluations = problem.n_evaluations
    evaluations = []
    for motor, demand in (designed, conventional):
        u = model_inputs(motor, demand, constraints)
        fisher = model.fisher(u, variance)
        scale = np.abs(model.theta) + (model.theta == 0)
        value = float(criterion_value(fisher * np.outer(scale, scale), criterion))
        evaluations.append((fisher, cramer_rao_covariance(fisher), value, model.simulate(u)))
    (fisher, cov, value, y), (fisher_c, cov_c, value_c, y_c) = evaluations
    motor, demand = designed
    lag = constraints.pressure_lag.apply(demand, constraints.sample_period, constraints.pressure_start)
    return PantographDesign(
        model.structure_name, model.parameter_names, dict(model.parameters), criterion,
        np.arange(model.length) * constraints.sample_period, motor, demand, lag,
        np.asarray(conventional[0]), np.asarray(conventional[1]), y, y_c, model.output_names,
        variance, fisher, cov, fisher_c, cov_c, value, value_c, constraints, history,
        n_evaluations, wall_time, message)
