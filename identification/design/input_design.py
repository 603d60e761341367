"""Optimal input design under amplitude and rate limits, offline and online (thesis section 5.4).

The design variable is the input increment :math:`\\Delta u` (eq. 5.9): the rate limit
:math:`|\\Delta u_i| \\le \\Delta u_{\\max}` is a box, the amplitude limit
:math:`|\\sum_{k \\le i} \\Delta u_k| \\le u_{\\max}` a set of linear inequalities
:math:`A \\Delta u \\le b` (:meth:`InputConstraints.linear_inequalities`).

Constraint handling (exact, not by penalty): the genetic algorithm searches the box of
increments, and every candidate is *repaired* before it is scored by sequential clipping,
:math:`u_i = \\operatorname{clip}(u_{i-1} + \\Delta u_i, u_{lo}, u_{hi})`. Because
:math:`u_{i-1}` already lies in :math:`[u_{lo}, u_{hi}]`, the clipped step is never longer than
the proposed one, so the repaired sequence meets both limits exactly, and a feasible candidate is
left unchanged (the repair is a projection onto the feasible set along the sequence).

* :func:`design_offline`: GA (:class:`pymoo.algorithms.soo.nonconvex.ga.GA`, whole population
  scored in one vectorised call) over the whole experiment, started from a conventional input
  (the thesis' two-sine signal) and perturbations of it.
* :func:`panto.identification.design.online_design.design_online`: recursive least squares and a receding
  horizon (the same GA, problem and repair on the next `horizon` increments at each sample).

Any model works that has ``parameter_names`` and ``sensitivities(theta, inputs) -> (outputs,
psi)`` for inputs of shape ``(..., N, n_inputs)`` and sensitivities ``(..., N, n_outputs,
n_theta)`` (e.g. :class:`panto.identification.design.oscillator.TransferFunctionModel`); the online
design also needs ``regressor(inputs, outputs, k)`` and ``is_stable(theta)`` (an ARX-type
model, for RLS).
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from pymoo.algorithms.soo.nonconvex.ga import GA
from pymoo.core.problem import Problem
from pymoo.core.repair import Repair
from pymoo.optimize import minimize

from panto.identification.design.fisher import (
    CRITERIA,
    cramer_rao_covariance,
    criterion_cost,
    criterion_value,
    fisher_information,
)

Progress = Callable[[str], None]


class SensitivityModel(Protocol):
    """A discrete-time model with output sensitivities (see the module docstring)."""

    parameter_names: tuple[str, ...]

    def sensitivities(self, theta: Sequence[float],
                      inputs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outputs ``(..., N, n_outputs)`` and :math:`\\partial y / \\partial \\theta`
        ``(..., N, n_outputs, n_theta)`` for inputs ``(..., N, n_inputs)``."""


@dataclass(frozen=True)
class InputConstraints:
    """Amplitude and rate limits of the inputs (eqs. 5.7-5.8), per input.

    Parameters
    ----------
    lower, upper : float or tuple of float
        Amplitude range :math:`u_{lo} \\le u \\le u_{hi}` per input.
    rate : float or tuple of float
        Largest increment per sample :math:`|\\Delta u| \\le \\Delta u_{\\max}`.
    initial : float or tuple of float
        The input before the first sample (the increments start from it).
    """

    lower: float | tuple[float, ...]
    upper: float | tuple[float, ...]
    rate: float | tuple[float, ...]
    initial: float | tuple[float, ...] = 0.0

    def __post_init__(self) -> None:
        lower, upper, rate, initial = self.arrays()
        if np.any(~(upper > lower)) or np.any(~(rate > 0)):
            raise ValueError(f"input constraints need upper > lower and rate > 0, got "
                             f"lower={self.lower}, upper={self.upper}, rate={self.rate}")
        if np.any(initial < lower) or np.any(initial > upper):
            raise ValueError(f"initial input {self.initial} outside [{self.lower}, {self.upper}]")

    @classmethod
    def symmetric(cls, amplitude: float, rate: float, initial: float = 0.0) -> InputConstraints:
        """:math:`|u| \\le` amplitude, :math:`|\\Delta u| \\le` rate (the thesis' form)."""
        return cls(-amplitude, amplitude, rate, initial)

    @property
    def n_inputs(self) -> int:
        """Number of inputs the limits are given for (1 for scalars)."""
        return int(np.broadcast(*(np.atleast_1d(v) for v in
                                  (self.lower, self.upper, self.rate, self.initial))).shape[0])

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """lower, upper, rate, initial as float arrays of shape (n_inputs,)."""
        values = np.broadcast_arrays(*(np.atleast_1d(np.asarray(v, float)) for v in
                                       (self.lower, self.upper, self.rate, self.initial)))
        return tuple(np.array(v) for v in values)

    def repair(self, increments: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """Feasible inputs from proposed increments by sequential clipping.

        Parameters
        ----------
        increments : ndarray, shape (..., N, n_inputs)
        start : ndarray, shape (n_inputs,), optional
            Input before the first increment (default :attr:`initial`).

        Returns
        -------
        ndarray, shape (..., N, n_inputs)
            Inputs within [lower, upper] whose increments are within [-rate, rate].
        """
        lower, upper, rate, initial = self.arrays()
        steps = np.clip(np.asarray(increments, float), -rate, rate)
        inputs = np.empty_like(steps)
        previous = np.broadcast_to(initial if start is None else np.asarray(start, float),
                                   steps[..., 0, :].shape)
        for i in range(steps.shape[-2]):
            previous = np.clip(previous + steps[..., i, :], lower, upper)
            inputs[..., i, :] = previous
        return inputs

    def increments(self, inputs: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """:math:`\\Delta u_i = u_i - u_{i-1}` with :math:`u_0` = `start` (default initial)."""
        _, _, _, initial = self.arrays()
        inputs = np.asarray(inputs, float)
        first = np.broadcast_to(initial if start is None else start, inputs[..., :1, :].shape)
        return np.diff(np.concatenate([first, inputs], axis=-2), axis=-2)

    def linear_inequalities(self, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """:math:`A \\Delta u \\le b` of problem 5.9 for increments flattened ``(N, n_inputs)``.

        Rows: :math:`\\pm\\Delta u \\le \\Delta u_{\\max}` and :math:`\\pm(u_0 + L\\Delta u)`
        within the amplitude range, :math:`L` the lower-triangular matrix of ones (cumulative
        sum) per input.
        """
        lower, upper, rate, initial = self.arrays()
        n_inputs = lower.size
        identity = np.eye(n_samples * n_inputs)
        cumulative = np.kron(np.tril(np.ones((n_samples, n_samples))), np.eye(n_inputs))
        a = np.vstack([identity, -identity, cumulative, -cumulative])
        b = np.concatenate([np.tile(rate, n_samples), np.tile(rate, n_samples),
                            np.tile(upper - initial, n_samples),
                            np.tile(initial - lower, n_samples)])
        return a, b

    def violation(self, inputs: np.ndarray, start: np.ndarray | None = None) -> float:
        """Largest violation of any limit by `inputs` (N, n_inputs); <= 0 when feasible."""
        lower, upper, rate, _ = self.arrays()
        inputs = np.asarray(inputs, float)
        steps = np.abs(self.increments(inputs, start))
        return float(max(np.max(inputs - upper), np.max(lower - inputs), np.max(steps - rate)))


@dataclass(frozen=True)
class GeneticOptions:
    """Settings of the genetic algorithm (pymoo GA: tournament, SBX crossover, PM mutation).

    ``spread`` is the standard deviation, as a fraction of the rate limit, of the perturbations
    of the start input that fill the initial population.
    """

    population: int = 60
    generations: int = 200
    spread: float = 0.3
    seed: int = 0

    def __post_init__(self) -> None:
        if self.population < 4 or self.generations < 1 or self.spread < 0:
            raise ValueError(f"GeneticOptions need population >= 4, generations >= 1, "
                             f"spread >= 0, got {self}")


@dataclass(frozen=True)
class OfflineDesign:
    """An offline input design (whole experiment optimised before the run).

    Parameters
    ----------
    inputs, increments, start_inputs : ndarray, shape (N, n_inputs)
    theta : ndarray
        Parameter guess the design is computed at.
    criterion : str
    noise_variance : float or ndarray
    fisher, covariance : ndarray, shape (n_theta, n_theta)
        Fisher information of the design and its Cramer-Rao covariance (at `theta`).
    value : float
        Criterion value (A: tr M^-1, D: log det M, E: lambda_min).
    start_fisher, start_covariance, start_value
        The same for the start input.
    history : ndarray
        Best cost per generation.
    n_evaluations : int
    wall_time : float
        Seconds.
    message : str
    """

    inputs: np.ndarray
    increments: np.ndarray
    start_inputs: np.ndarray
    theta: np.ndarray
    criterion: str
    noise_variance: float | np.ndarray
    fisher: np.ndarray
    covariance: np.ndarray
    value: float
    start_fisher: np.ndarray
    start_covariance: np.ndarray
    start_value: float
    history: np.ndarray
    n_evaluations: int
    wall_time: float
    message: str


def as_input_matrix(inputs: np.ndarray, constraints: InputConstraints) -> np.ndarray:
    """`inputs` as a float array of shape (N, n_inputs) (a 1-D array is one input); checks the shape."""
    array = np.asarray(inputs, float)
    array = array[:, None] if array.ndim == 1 else array
    if array.ndim != 2 or array.shape[1] != constraints.n_inputs:
        raise ValueError(f"start inputs must have shape (N, {constraints.n_inputs}), got "
                         f"{np.shape(inputs)}")
    return array


class SequenceRepair(Repair):
    """pymoo repair: flattened increments -> increments of the clipped (feasible) inputs."""

    def __init__(self, constraints: InputConstraints, shape: tuple[int, int],
                 start: np.ndarray | None) -> None:
        super().__init__()
        self.constraints, self.shape, self.start = constraints, shape, start

    def _do(self, problem, X, **kwargs):
        increments = X.reshape(-1, *self.shape)
        inputs = self.constraints.repair(increments, self.start)
        return self.constraints.increments(inputs, self.start).reshape(len(X), -1)


class DesignProblem(Problem):
    """Minimise the criterion cost of past inputs (fixed) followed by the candidate inputs."""

    def __init__(self, model: SensitivityModel, theta: np.ndarray, constraints: InputConstraints,
                 shape: tuple[int, int], criterion: str, noise_variance: float | np.ndarray,
                 past: np.ndarray, start: np.ndarray, regularisation: np.ndarray) -> None:
        _, _, rate, _ = constraints.arrays()
        bound = np.tile(rate, shape[0])
        super().__init__(n_var=bound.size, n_obj=1, xl=-bound, xu=bound)
        self.model, self.theta, self.shape, self.past = model, theta, shape, past
        self.criterion, self.noise_variance = criterion, noise_variance
        self.start, self.regularisation = start, regularisation
        self.n_evaluations = 0

    def costs(self, increments: np.ndarray) -> np.ndarray:
        """Criterion cost per row of flattened increments (non-finite costs as 1e300)."""
        candidates = self.start + np.cumsum(increments.reshape(-1, *self.shape), axis=-2)
        past = np.broadcast_to(self.past, (len(candidates), *self.past.shape))
        _, psi = self.model.sensitivities(self.theta, np.concatenate([past, candidates], axis=-2))
        fisher = fisher_information(psi, self.noise_variance) + self.regularisation
        self.n_evaluations += len(candidates)
        cost = np.asarray(criterion_cost(fisher, self.criterion), float)
        return np.where(np.isfinite(cost), cost, 1e300)

    def _evaluate(self, x, out, *args, **kwargs):
        out["F"] = self.costs(np.atleast_2d(x))


def _initial_population(seeds: np.ndarray, options: GeneticOptions, rate: np.ndarray,
                        rng: np.random.Generator) -> np.ndarray:
    """Seeds (rows of flattened increments) plus Gaussian perturbations of them."""
    seeds = np.atleast_2d(seeds)
    n_extra = options.population - len(seeds)
    picks = seeds[rng.integers(0, len(seeds), n_extra)]
    scale = np.tile(rate, seeds.shape[1] // rate.size) * options.spread
    return np.vstack([seeds, picks + rng.normal(size=picks.shape) * scale])


def run_genetic(problem: DesignProblem, seeds: np.ndarray, options: GeneticOptions,
                repair: SequenceRepair, rate: np.ndarray,
                on_generation: Callable[[int, float], None] | None = None):
    """Minimise `problem` with pymoo's GA from `seeds` and their perturbations (scaled by `rate`),
    repaired to feasible sequences; returns the best increments and the best cost per generation."""
    rng = np.random.default_rng(options.seed)
    population = repair._do(problem, _initial_population(seeds, options, rate, rng))
    history: list[float] = []

    def callback(algorithm) -> None:
        history.append(float(algorithm.opt.get("F").min()))
        if on_generation is not None:
            on_generation(algorithm.n_gen, history[-1])

    algorithm = GA(pop_size=options.population, sampling=population, repair=repair,
                   eliminate_duplicates=False)
    result = minimize(problem, algorithm, ("n_gen", options.generations), seed=options.seed,
                      verbose=False, callback=callback)
    return np.asarray(result.X, float), np.asarray(history)


def regularising_prior(n_theta: int, noise_variance: float | np.ndarray) -> np.ndarray:
    """A tiny prior information, so that short (early online) experiments are not singular."""
    return 1e-9 / float(np.min(noise_variance)) * np.eye(n_theta)


@dataclass(frozen=True)
class OfflineOptions:
    """What the offline design maximises and the GA that searches for it."""

    criterion: str = "D"
    """Criterion of the Fisher information: ``A`` (tr M^-1), ``D`` (log det M), ``E``
    (lambda_min)."""
    noise_variance: float | np.ndarray = 1.0
    """Output noise variance :math:`\\sigma^2` per output [output unit^2]."""
    genetic: GeneticOptions = GeneticOptions()
    """The GA over the whole experiment."""

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {self.criterion!r}")


def design_offline(model: SensitivityModel, theta: Sequence[float], start_inputs: np.ndarray,
                   constraints: InputConstraints, *, options: OfflineOptions = OfflineOptions(),
                   progress: Progress | None = None) -> OfflineDesign:
    """Offline DoE (thesis section 5.4, steps 1-4): the whole input optimised by a GA.

    Parameters
    ----------
    model : SensitivityModel
    theta : sequence of float
        Best prior guess of the parameters (the design depends on it).
    start_inputs : ndarray, shape (N,) or (N, n_inputs)
        Start of the search (the thesis' two-sine input); repaired first if infeasible.
    constraints : InputConstraints
    options : OfflineOptions
        Criterion, noise variance per output, GA settings.
    progress : callable, optional
        Receives a line about every tenth of the generations.
    """
    criterion, noise_variance = options.criterion, options.noise_variance
    genetic = options.genetic
    began = time.perf_counter()
    theta = np.asarray(theta, float)
    start_inputs = constraints.repair(constraints.increments(as_input_matrix(start_inputs,
                                                                             constraints)))
    shape = start_inputs.shape
    _, _, rate, initial = constraints.arrays()
    regularisation = regularising_prior(theta.size, noise_variance)
    problem = DesignProblem(model, theta, constraints, shape, criterion, noise_variance,
                            np.zeros((0, shape[1])), initial, regularisation)
    repair = SequenceRepair(constraints, shape, None)
    every = max(1, genetic.generations // 10)

    def report(generation: int, best: float) -> None:
        if progress is not None and (generation % every == 0 or generation == 1):
            progress(f"offline DoE: generation {generation}/{genetic.generations}, "
                     f"best cost {best:.6g}")

    best, history = run_genetic(problem, constraints.increments(start_inputs).reshape(1, -1),
                                genetic, repair, rate, report)
    inputs = constraints.repair(best.reshape(shape))
    fisher = inputs_fisher_information(model, theta, inputs, noise_variance)
    start_fisher = inputs_fisher_information(model, theta, start_inputs, noise_variance)
    return OfflineDesign(
        inputs, constraints.increments(inputs), start_inputs, theta, criterion, noise_variance,
        fisher, cramer_rao_covariance(fisher), float(criterion_value(fisher, criterion)),
        start_fisher, cramer_rao_covariance(start_fisher),
        float(criterion_value(start_fisher, criterion)), history, problem.n_evaluations,
        time.perf_counter() - began,
        f"GA: {genetic.generations} generations of {genetic.population}")


def inputs_fisher_information(model: SensitivityModel, theta: np.ndarray, inputs: np.ndarray,
                              noise_variance: float | np.ndarray) -> np.ndarray:
    """Fisher information (eq. 5.6) of `model` at `theta` for the input sequence `inputs`."""
    _, psi = model.sensitivities(theta, inputs)
    return fisher_information(psi, noise_variance)
