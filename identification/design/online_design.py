"""Online input design: recursive least squares and a receding horizon (thesis section 5.4).

At every sample the newest measurement updates the parameter estimate by RLS, the next `horizon`
input increments are optimised (GA, constraints repaired exactly as in
:mod:`panto.identification.design.input_design`) for the criterion of the Fisher information accumulated over
the inputs already applied plus the horizon, at the current estimate, and the first one is
applied: "the genetic algorithm is started with a shorter horizon and the state vector is not
initialised zero but with the past values" (thesis). :class:`SimulatedPlant` stands in for the
rig in simulations; on the rig, any callable returning the newest measurement does.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from panto.identification.design.oscillator import RecursiveLeastSquares
from panto.identification.design.fisher import CRITERIA, cramer_rao_covariance, criterion_value
from panto.identification.design.input_design import (
    GeneticOptions,
    InputConstraints,
    Progress,
    SensitivityModel,
    DesignProblem,
    SequenceRepair,
    as_input_matrix,
    inputs_fisher_information,
    regularising_prior,
    run_genetic,
)


class Plant(Protocol):
    """The system under test: ``plant(inputs)`` returns the measurement y(k), shape (n_outputs,),
    after the inputs u(0..k-1) (``inputs`` of shape (k, n_inputs); k = 0 gives y(0))."""

    def __call__(self, inputs: np.ndarray) -> np.ndarray: ...


@dataclass
class SimulatedPlant:
    """A model with fixed true parameters plus white Gaussian output noise (for simulations)."""

    model: SensitivityModel
    theta: np.ndarray
    noise_std: float
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))

    def __call__(self, inputs: np.ndarray) -> np.ndarray:
        inputs = np.asarray(inputs, float)
        inputs = inputs[:, None] if inputs.ndim == 1 else inputs
        padded = np.concatenate([inputs, np.zeros((1, inputs.shape[1]))])
        outputs, _ = self.model.sensitivities(self.theta, padded)
        return outputs[-1] + self.noise_std * self.rng.normal(size=outputs.shape[-1])


@dataclass(frozen=True)
class OnlineOptions:
    """What the online design maximises and its receding-horizon settings: `horizon` future
    inputs optimised per sample by a small GA."""

    criterion: str = "D"
    """Criterion of the Fisher information, one of ``A``, ``D``, ``E``."""
    noise_variance: float | np.ndarray = 1.0
    """Output noise variance :math:`\\sigma^2` per output [output unit^2]."""
    horizon: int = 20
    """Future inputs optimised per sample [samples]."""
    genetic: GeneticOptions = field(
        default_factory=lambda: GeneticOptions(population=20, generations=12))
    """The GA run per sample (its seed is advanced by the sample index)."""
    initial_covariance: float = 1e6
    """:math:`p_0` of the RLS start :math:`P_0 = p_0 I`."""
    forgetting: float = 1.0
    """RLS forgetting factor (1: none)."""

    def __post_init__(self) -> None:
        if self.criterion not in CRITERIA:
            raise ValueError(f"criterion must be one of {CRITERIA}, got {self.criterion!r}")
        if self.horizon < 1:
            raise ValueError(f"horizon must be at least 1, got {self.horizon}")


@dataclass(frozen=True)
class OnlineDesign:
    """An online input design (each input chosen during the run).

    Parameters
    ----------
    inputs, increments, start_inputs : ndarray, shape (N, n_inputs)
    outputs : ndarray, shape (N, n_outputs)
        Measurements y(0..N-1).
    theta : ndarray
        Final RLS estimate.
    theta_history : ndarray, shape (N, n_theta)
        Estimate after each sample.
    rls_covariance : ndarray
        Final RLS matrix P (proportional to the covariance; thesis eqs. 5.26-5.28).
    criterion : str
    noise_variance : float or ndarray
    fisher, covariance : ndarray
        Fisher information of the applied input and its Cramer-Rao covariance at `theta`.
    value : float
        Criterion value at `theta`.
    step_times : ndarray, shape (N,)
        Seconds per sample (RLS update + horizon optimisation).
    n_evaluations : int
    wall_time : float
    message : str
    """

    inputs: np.ndarray
    increments: np.ndarray
    start_inputs: np.ndarray
    outputs: np.ndarray
    theta: np.ndarray
    theta_history: np.ndarray
    rls_covariance: np.ndarray
    criterion: str
    noise_variance: float | np.ndarray
    fisher: np.ndarray
    covariance: np.ndarray
    value: float
    step_times: np.ndarray
    n_evaluations: int
    wall_time: float
    message: str


def design_online(model: SensitivityModel, plant: Plant, theta_initial: Sequence[float],
                  start_inputs: np.ndarray, constraints: InputConstraints, *,
                  options: OnlineOptions = OnlineOptions(),
                  progress: Progress | None = None) -> OnlineDesign:
    """Online DoE (thesis section 5.4): RLS estimate and receding-horizon design per sample.

    At sample k: measure y(k); update :math:`\\hat\\theta` by RLS with
    :math:`\\varphi(k)` (``model.regressor``); if :math:`\\hat\\theta` is stable (else the last
    stable estimate) optimise u(k..k+H-1), H = min(horizon, N - k), for the criterion of the
    Fisher information of u(0..k+H-1) at :math:`\\hat\\theta` (past inputs fixed: the
    sensitivity filters start from the past, not from zero); apply u(k). The GA starts from the
    previous step's horizon shifted by one sample and from the start input's increments.

    Parameters
    ----------
    model : SensitivityModel
        Also needs ``regressor(inputs, outputs, k)`` and ``is_stable(theta)``.
    plant : Plant
        The system run (e.g. :class:`SimulatedPlant`); called once per sample.
    theta_initial : sequence of float
        Prior guess, start of the RLS.
    start_inputs : ndarray, shape (N,) or (N, n_inputs)
        Length of the experiment, and the GA's seed.
    constraints : InputConstraints
        As for :func:`~panto.identification.design.input_design.design_offline`.
    options : OnlineOptions
        Criterion, noise variance, horizon, GA and RLS settings.
    progress : callable, optional
        Receives a line about every tenth of the samples.
    """
    began = time.perf_counter()
    start_inputs = constraints.repair(constraints.increments(as_input_matrix(start_inputs,
                                                                             constraints)))
    run = _OnlineRun.start(model, constraints, options, start_inputs, theta_initial)
    n_samples = len(start_inputs)
    every = max(1, n_samples // 10)
    for k in range(n_samples):
        tick = time.perf_counter()
        run.measure(plant, k)
        run.plan(k)
        run.step_times[k] = time.perf_counter() - tick
        if progress is not None and ((k + 1) % every == 0 or k + 1 == n_samples):
            progress(f"online DoE: sample {k + 1}/{n_samples}, theta {np.round(run.rls.theta, 4)}, "
                     f"{1e3 * run.step_times[k]:.1f} ms")
    return run.result(start_inputs, time.perf_counter() - began)


@dataclass
class _OnlineRun:
    """The state of one online design: the RLS, the inputs applied, the plan and the counters."""

    model: SensitivityModel
    constraints: InputConstraints
    options: OnlineOptions
    rls: RecursiveLeastSquares
    design_theta: np.ndarray
    regularisation: np.ndarray
    start_steps: np.ndarray
    planned: np.ndarray
    inputs: np.ndarray
    history: np.ndarray
    step_times: np.ndarray
    outputs: list = field(default_factory=list)
    n_evaluations: int = 0

    @classmethod
    def start(cls, model: SensitivityModel, constraints: InputConstraints, options: OnlineOptions,
              start_inputs: np.ndarray, theta_initial: Sequence[float]) -> _OnlineRun:
        """Before the first sample: the RLS at the prior guess, the plan = the start input."""
        n_samples, n_inputs = start_inputs.shape
        start_steps = constraints.increments(start_inputs)
        rls = RecursiveLeastSquares.start(theta_initial, options.initial_covariance,
                                          options.forgetting)
        design_theta = rls.theta.copy()
        return cls(model, constraints, options, rls, design_theta,
                   regularising_prior(design_theta.size, options.noise_variance), start_steps,
                   start_steps.copy(), np.zeros((n_samples, n_inputs)),
                   np.zeros((n_samples, design_theta.size)), np.zeros(n_samples))

    def measure(self, plant: Plant, k: int) -> None:
        """Measure y(k) after u(0..k-1), update the RLS, keep the estimate if it is stable."""
        self.outputs.append(np.atleast_1d(plant(self.inputs[:k])))
        measured = np.array(self.outputs)
        if k > 0:
            self.rls.update(self.model.regressor(self.inputs[:k, 0], measured[:, 0], k),
                            measured[k, 0])
        if self.model.is_stable(self.rls.theta):
            self.design_theta = self.rls.theta.copy()
        self.history[k] = self.rls.theta

    def plan(self, k: int) -> None:
        """Optimise u(k..k+H-1) by the GA and apply u(k)."""
        constraints, options = self.constraints, self.options
        n_inputs = self.inputs.shape[1]
        horizon = min(options.horizon, len(self.inputs) - k)
        previous = self.inputs[k - 1] if k > 0 else constraints.arrays()[3]
        seeds = np.stack([self.planned[k:k + horizon],
                          self.start_steps[k:k + horizon]]).reshape(2, -1)
        problem = DesignProblem(self.model, self.design_theta, constraints, (horizon, n_inputs),
                                options.criterion, options.noise_variance, self.inputs[:k],
                                previous, self.regularisation)
        repair = SequenceRepair(constraints, (horizon, n_inputs), previous)
        genetic = replace(options.genetic, seed=options.genetic.seed + k)
        best, _ = run_genetic(problem, seeds, genetic, repair, constraints.arrays()[2])
        chosen = constraints.repair(best.reshape(horizon, n_inputs), previous)
        self.inputs[k] = chosen[0]
        self.planned[k:k + horizon] = constraints.increments(chosen, previous)
        self.n_evaluations += problem.n_evaluations

    def result(self, start_inputs: np.ndarray, wall_time: float) -> OnlineDesign:
        """The design after the last sample, its Fisher information at the final estimate."""
        options, theta = self.options, self.rls.theta.copy()
        fisher = inputs_fisher_information(self.model, theta, self.inputs, options.noise_variance)
        return OnlineDesign(
            self.inputs, self.constraints.increments(self.inputs), start_inputs,
            np.array(self.outputs), theta, self.history, self.rls.covariance.copy(),
            options.criterion, options.noise_variance, fisher, cramer_rao_covariance(fisher),
            float(criterion_value(fisher, options.criterion)), self.step_times,
            self.n_evaluations, wall_time,
            f"RLS + receding horizon {options.horizon}, GA {options.genetic.generations} "
            f"generations of {options.genetic.population} per sample")
