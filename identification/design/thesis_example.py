"""The thesis' dynamic DoE example end to end (section 5.4, eqs. 5.17-5.28, Table 5.1).

:func:`run_thesis_example` designs the offline input (GA at :math:`\\theta_{init}`), runs the
online design (RLS + receding horizon on a simulated oscillator with
:math:`\\sigma^2 = 10^{-10}` m^2), and evaluates the three inputs (two-sine, offline, online) as
the thesis does:

* the Cramer-Rao covariance at the true parameters (what the input promises),
* RLS on one noisy run from :math:`\\theta_{init}`: :math:`\\hat\\theta` and the matrix P
  (eqs. 5.26-5.28),
* the continuous-time grey-box estimate of m, c, k and its variances (Table 5.1).

:func:`monte_carlo_covariance` checks the promise empirically: output-error fits on many noisy
realisations of one input give the empirical parameter covariance.
"""
from __future__ import annotations

import csv
import json
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from panto.identification.design.oscillator import (
    AMPLITUDE_LIMIT,
    END_TIME,
    INITIAL_PHYSICAL,
    NOISE_VARIANCE,
    RATE_LIMIT,
    SAMPLE_PERIOD,
    TRUE_PHYSICAL,
    GreyBoxEstimate,
    RecursiveLeastSquares,
    TransferFunctionModel,
    discretise_oscillator,
    fit_grey_box,
    fit_output_error,
    physical_from_theta,
    two_sine_input,
)
from panto.identification.design.fisher import cramer_rao_covariance, fisher_information
from panto.identification.design.input_design import (
    GeneticOptions,
    InputConstraints,
    OfflineDesign,
    OfflineOptions,
    design_offline,
)
from panto.identification.design.online_design import (
    OnlineDesign,
    OnlineOptions,
    SimulatedPlant,
    design_online,
)

#: GA settings of the full example (offline: whole 30 s input; online: per sample).
THESIS_OFFLINE_OPTIONS = GeneticOptions(population=60, generations=300)
THESIS_ONLINE_OPTIONS = OnlineOptions()


@dataclass(frozen=True)
class InputEvaluation:
    """One input judged as in the thesis.

    Parameters
    ----------
    name : str
    inputs, outputs : ndarray, shape (N,)
        Force [N] and the noisy measured position [m].
    cramer_rao : ndarray, shape (4, 4)
        :math:`\\sigma^2 (\\Psi^T\\Psi)^{-1}` at the true :math:`\\theta`.
    rls_theta : ndarray, shape (4,)
    rls_matrix : ndarray, shape (4, 4)
        RLS P after the run (from :math:`\\theta_{init}`, :math:`P_0 = 10^6 I`).
    grey_box : GreyBoxEstimate
    """

    name: str
    inputs: np.ndarray
    outputs: np.ndarray
    cramer_rao: np.ndarray
    rls_theta: np.ndarray
    rls_matrix: np.ndarray
    grey_box: GreyBoxEstimate


@dataclass(frozen=True)
class ThesisExample:
    """Result of :func:`run_thesis_example`."""

    theta_true: np.ndarray
    theta_initial: np.ndarray
    offline: OfflineDesign
    online: OnlineDesign
    evaluations: dict[str, InputEvaluation]
    settings: dict[str, float]

    def variance_ratios(self, reference: str = "sine") -> dict[str, np.ndarray]:
        """Cramer-Rao variance of each parameter: reference / input (> 1 is better)."""
        base = np.diag(self.evaluations[reference].cramer_rao)
        return {name: base / np.diag(e.cramer_rao) for name, e in self.evaluations.items()}

    def summary(self) -> dict:
        """JSON-ready summary (settings, designs, per-input estimates and covariances)."""
        ratios = self.variance_ratios()
        return {
            "settings": self.settings,
            "theta_true": self.theta_true.tolist(), "theta_initial": self.theta_initial.tolist(),
            "offline": {"criterion": self.offline.criterion, "value": self.offline.value,
                        "start_value": self.offline.start_value,
                        "wall_time_s": self.offline.wall_time,
                        "n_evaluations": self.offline.n_evaluations,
                        "message": self.offline.message},
            "online": {"wall_time_s": self.online.wall_time,
                       "mean_step_s": float(np.mean(self.online.step_times)),
                       "max_step_s": float(np.max(self.online.step_times)),
                       "n_evaluations": self.online.n_evaluations,
                       "message": self.online.message},
            "inputs": {name: {
                "cramer_rao_variance": np.diag(e.cramer_rao).tolist(),
                "variance_ratio_vs_sine": ratios[name].tolist(),
                "rls_theta": e.rls_theta.tolist(), "rls_P": e.rls_matrix.tolist(),
                "rls_m_c_k": physical_from_theta(e.rls_theta).tolist(),
                "grey_box_m_c_k": e.grey_box.values.tolist(),
                "grey_box_variance": e.grey_box.variances.tolist()}
                for name, e in self.evaluations.items()},
        }

    def write(self, folder: str | Path) -> list[Path]:
        """Write ``doe_example.json`` and ``doe_example_inputs.csv`` into `folder`."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        summary = folder / "doe_example.json"
        summary.write_text(json.dumps(self.summary(), indent=2))
        table = folder / "doe_example_inputs.csv"
        names = list(self.evaluations)
        with table.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["time_s"] + [f"{n}_force_N" for n in names] +
                            [f"{n}_position_m" for n in names])
            for k in range(len(self.evaluations[names[0]].inputs)):
                writer.writerow([k * self.settings["sample_period"]] +
                                [self.evaluations[n].inputs[k] for n in names] +
                                [self.evaluations[n].outputs[k] for n in names])
        return [summary, table]


def estimate_by_rls(model: TransferFunctionModel, inputs: np.ndarray, outputs: np.ndarray,
                    theta_initial: np.ndarray,
                    initial_covariance: float = 1e6) -> tuple[np.ndarray, np.ndarray]:
    """RLS over a whole record: final :math:`\\hat\\theta` and P (as eqs. 5.26-5.28)."""
    rls = RecursiveLeastSquares.start(theta_initial, initial_covariance)
    for k in range(1, len(inputs)):
        rls.update(model.regressor(inputs[:k], outputs[:k], k), outputs[k])
    return rls.theta.copy(), rls.covariance.copy()


def evaluate_input(name: str, inputs: np.ndarray, *, outputs: np.ndarray | None = None,
                   noise_variance: float = NOISE_VARIANCE,
                   rng: np.random.Generator | None = None) -> InputEvaluation:
    """Judge an input on the thesis' oscillator (measured `outputs` or a fresh noisy run)."""
    model = TransferFunctionModel()
    theta_true = discretise_oscillator(*TRUE_PHYSICAL)
    u = np.ravel(inputs)
    _, psi = model.sensitivities(theta_true, u)
    if outputs is None:
        rng = np.random.default_rng(0) if rng is None else rng
        outputs = model.simulate(theta_true, u)[:, 0] + np.sqrt(noise_variance) * rng.normal(size=u.size)
    y = np.ravel(outputs)
    rls_theta, rls_matrix = estimate_by_rls(model, u, y, discretise_oscillator(*INITIAL_PHYSICAL))
    return InputEvaluation(name, u, y, cramer_rao_covariance(fisher_information(psi, noise_variance)),
                           rls_theta, rls_matrix, fit_grey_box(u, y, SAMPLE_PERIOD))


def monte_carlo_covariance(inputs: np.ndarray, n_realisations: int, *,
                           noise_variance: float = NOISE_VARIANCE,
                           rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Empirical covariance of output-error estimates of :math:`\\theta` over noisy realisations.

    Returns the estimates, shape (R, 4), and their sample covariance (4, 4).
    """
    rng = np.random.default_rng(0) if rng is None else rng
    model = TransferFunctionModel()
    theta_true = discretise_oscillator(*TRUE_PHYSICAL)
    u = np.ravel(inputs)
    clean = model.simulate(theta_true, u)[:, 0]
    estimates = np.array([
        fit_output_error(model, u, clean + np.sqrt(noise_variance) * rng.normal(size=u.size),
                         theta_true, iterations=4) for _ in range(n_realisations)])
    return estimates, np.cov(estimates, rowvar=False)


def run_thesis_example(*, end_time: float = END_TIME, criterion: str = "D",
                       offline_options: GeneticOptions = THESIS_OFFLINE_OPTIONS,
                       online_options: OnlineOptions = THESIS_ONLINE_OPTIONS, seed: int = 0,
                       progress: Callable[[str], None] | None = None) -> ThesisExample:
    """The thesis' section 5.4 example: offline and online designs against the two-sine input."""
    n_samples = round(end_time / SAMPLE_PERIOD)
    model = TransferFunctionModel()
    theta_true = discretise_oscillator(*TRUE_PHYSICAL)
    theta_initial = discretise_oscillator(*INITIAL_PHYSICAL)
    constraints = InputConstraints.symmetric(AMPLITUDE_LIMIT, RATE_LIMIT)
    sine = two_sine_input(n_samples, SAMPLE_PERIOD)
    offline = design_offline(model, theta_initial, sine, constraints,
                             options=OfflineOptions(criterion, NOISE_VARIANCE, offline_options),
                             progress=progress)
    plant = SimulatedPlant(model, theta_true, float(np.sqrt(NOISE_VARIANCE)),
                           np.random.default_rng(seed + 1))
    online = design_online(model, plant, theta_initial, sine, constraints,
                           options=replace(online_options, criterion=criterion,
                                           noise_variance=NOISE_VARIANCE),
                           progress=progress)
    rng = np.random.default_rng(seed)
    evaluations = {
        "sine": evaluate_input("sine", sine, rng=rng),
        "offline": evaluate_input("offline", offline.inputs, rng=rng),
        "online": evaluate_input("online", online.inputs, outputs=online.outputs[:, 0]),
    }
    settings = {"end_time": end_time, "sample_period": SAMPLE_PERIOD,
                "noise_variance": NOISE_VARIANCE, "rate_limit": RATE_LIMIT,
                "amplitude_limit": AMPLITUDE_LIMIT, "horizon": online_options.horizon,
                "seed": seed}
    return ThesisExample(theta_true, theta_initial, offline, online, evaluations, settings)
