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
from dataclasses import dataclass, field
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
    """Receding-horizon settings: `horizon` future inputs optimised per sample by a small GA.

    ``initial_covariance`` is :math:`p_0` of the RLS start :math:`P_0 = p_0 I`.
    """

    horizon: int = 20
    genetic: GeneticOptions = field(
        default_factory=lambda: GeneticOptions(population=20, generations=12))
    initial_covariance: float = 1e6
    forgetting: float = 1.0

    def __post_init__(self) -> None:
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
                  criterion: str = "D", noise_variance: float | np.ndarray = 1.0,
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
    constraints, criterion, noise_variance
        As for :func:`design_offline`.
    options : OnlineOptions
    progress : callable, optional
        Receives a line about every tenth of the samples.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    began = time.perf_counter()
    start_inputs = constraints.repair(constraints.increments(as_input_matrix(start_inputs,
                                                                             constraints)))
    n_samples, n_inputs = start_inputs.shape
    start_steps = constraints.increments(start_inputs)
    _, _, rate, initial = constraints.arrays()
    rls = RecursiveLeastSquares.start(theta_initial, options.initial_covariance, options.forgetting)
    design_theta = rls.theta.copy()
    regularisation = regularising_prior(design_theta.size, noise_variance)
    inputs = np.zeros((n_samples, n_inputs))
    outputs, history, step_times = [], np.zeros((n_samples, design_theta.size)), np.zeros(n_samples)
    planned = start_steps.copy()
    n_evaluations, every = 0, max(1, n_samples // 10)
    for k in range(n_samples):
        tick = time.perf_counter()
        outputs.append(np.atleast_1d(plant(inputs[:k])))
        measured = np.array(outputs)
        if k > 0:
            rls.update(model.regressor(inputs[:k, 0], measured[:, 0], k), measured[k, 0])
        if model.is_stable(rls.theta):
            design_theta = rls.theta.copy()
        horizon = min(options.horizon, n_samples - k)
        previous = inputs[k - 1] if k > 0 else initial
        seeds = np.stack([planned[k:k + horizon], start_steps[k:k + horizon]]).reshape(2, -1)
        problem = DesignProblem(model, design_theta, constraints, (horizon, n_inputs), criterion,
                                 noise_variance, inputs[:k], previous, regularisation)
        repair = SequenceRepair(constraints, (horizon, n_inputs), previous)
        genetic = GeneticOptions(options.genetic.population, options.genetic.generations,
                                 options.genetic.spread, options.genetic.seed + k)
        best, _ = run_genetic(problem, seeds, genetic, repair, rate)
        chosen = constraints.repair(best.reshape(horizon, n_inputs), previous)
        inputs[k] = chosen[0]
        planned[k:k + horizon] = constraints.increments(chosen, previous)
        n_evaluations += problem.n_evaluations
        history[k] = rls.theta
        step_times[k] = time.perf_counter() - tick
        if progress is not None and ((k + 1) % every == 0 or k + 1 == n_samples):
            progress(f"online DoE: sample {k + 1}/{n_samples}, theta {np.round(rls.theta, 4)}, "
                     f"{1e3 * step_times[k]:.1f} ms")
    fisher = inputs_fisher_information(model, rls.theta, inputs, noise_variance)
    return OnlineDesign(
        inputs, constraints.increments(inputs), start_inputs, np.array(outputs), rls.theta.copy(),
        history, rls.covariance.copy(), criterion, noise_variance, fisher,
        cramer_rao_covariance(fisher), float(criterion_value(fisher, criterion)), step_times,
        n_evaluations, time.perf_counter() - began,
        f"RLS + receding horizon {options.horizon}, GA {options.genetic.generations} generations "
        f"of {options.genetic.population} per sample")
