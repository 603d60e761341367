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
from panto.identification.design.fisher import (cramer_rao_covariance, criterion_value,
                                                fisher_information)
from panto.identification.design.input_design import (
    GeneticOptions,
    InputConstraints,
    OfflineDesign,
    OfflineOptions,
    design_offline,
    inputs_fisher_information,
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


@dataclass(frozen=True)
class NoiseSpread:
    """Estimates of one input over independent noise realisations (thesis eqs. 5.26-5.28,
    Table 5.1).

    Parameters
    ----------
    name : str
    rls_theta : ndarray, shape (R, 4)
        RLS :math:`\\hat\\theta` per realisation (from :math:`\\theta_{init}`, :math:`P_0 = 10^6 I`).
    rls_matrix : ndarray, shape (R, 4, 4)
        RLS P per realisation.
    grey_box : ndarray, shape (R, 3)
        Grey-box m [kg], c [N s/m], k [N/m] per realisation.
    grey_box_variance : ndarray, shape (R, 3)
        Their estimated variances.
    """

    name: str
    rls_theta: np.ndarray
    rls_matrix: np.ndarray
    grey_box: np.ndarray
    grey_box_variance: np.ndarray

    def z_scores(self, theta: np.ndarray) -> np.ndarray:
        """(theta - mean) / standard deviation of the RLS estimates, per parameter."""
        return (np.asarray(theta, float) - self.rls_theta.mean(axis=0)) / self.rls_theta.std(axis=0)


def noise_realisations(name: str, inputs: np.ndarray, n_realisations: int, *,
                       noise_variance: float = NOISE_VARIANCE, grey_box: bool = True,
                       rng: np.random.Generator | None = None) -> NoiseSpread:
    """:func:`evaluate_input`'s estimates over `n_realisations` noise draws of one input."""
    rng = np.random.default_rng(0) if rng is None else rng
    model = TransferFunctionModel()
    u = np.ravel(inputs)
    clean = model.simulate(discretise_oscillator(*TRUE_PHYSICAL), u)[:, 0]
    theta_initial = discretise_oscillator(*INITIAL_PHYSICAL)
    thetas, matrices, values, variances = [], [], [], []
    for _ in range(n_realisations):
        y = clean + np.sqrt(noise_variance) * rng.normal(size=u.size)
        theta, matrix = estimate_by_rls(model, u, y, theta_initial)
        thetas.append(theta)
        matrices.append(matrix)
        if grey_box:
            estimate = fit_grey_box(u, y, SAMPLE_PERIOD)
            values.append(estimate.values)
            variances.append(estimate.variances)
    empty = np.zeros((0, 3))
    return NoiseSpread(name, np.array(thetas), np.array(matrices),
                       np.array(values) if grey_box else empty,
                       np.array(variances) if grey_box else empty)


@dataclass(frozen=True)
class GradientDesign:
    """An input polished by a gradient-based optimiser on the offline criterion.

    Parameters
    ----------
    inputs : ndarray, shape (N,)
        Feasible force sequence [N].
    value, start_value : float
        Criterion value (D: log det M, A: tr M^-1) at the result and at the start.
    success : bool
    message : str
    n_iterations : int
    """

    inputs: np.ndarray
    value: float
    start_value: float
    success: bool
    message: str
    n_iterations: int


def _impulse_sensitivities(model: TransferFunctionModel, theta: np.ndarray,
                           n_samples: int) -> np.ndarray:
    """Lower-triangular Toeplitz matrices ``H[p]`` with :math:`\\psi_p = H_p u` (the model is
    linear in u), shape (n_theta, N, N)."""
    impulse = np.zeros(n_samples)
    impulse[0] = 1.0
    response = model.sensitivities(theta, impulse)[1][:, 0, :]       # (N, n_theta)
    rows = np.arange(n_samples)[:, None] - np.arange(n_samples)[None, :]
    lower = rows >= 0
    return np.stack([np.where(lower, response[np.clip(rows, 0, None), j], 0.0)
                     for j in range(response.shape[1])])


def design_by_gradient(theta: np.ndarray, start_inputs: np.ndarray, *,
                       criterion: str = "D", noise_variance: float = NOISE_VARIANCE,
                       amplitude: float = AMPLITUDE_LIMIT, rate: float = RATE_LIMIT,
                       max_iterations: int = 200) -> GradientDesign:
    """Maximise the offline criterion by SLSQP with the exact gradient (problem 5.9).

    The model output is linear in u, so :math:`\\Psi = [H_1 u, .., H_4 u]` and, with
    :math:`M = \\Psi^T\\Psi/\\sigma^2`, :math:`\\partial \\log\\det M/\\partial u =
    (2/\\sigma^2) \\sum_p H_p^T (\\Psi M^{-1})_{:,p}` and :math:`\\partial\\,\\mathrm{tr}M^{-1}/
    \\partial u = -(2/\\sigma^2) \\sum_p H_p^T (\\Psi M^{-2})_{:,p}`. Constraints: :math:`|u| \\le`
    `amplitude` (bounds) and :math:`|u_i - u_{i-1}| \\le` `rate` with :math:`u_{-1} = 0` (linear).
    Used to check that the GA reached the optimum (docs/thesis.md, chapter 5).
    """
    if criterion not in ("A", "D"):
        raise ValueError(f"criterion must be 'A' or 'D' for the gradient design, got {criterion!r}")
    from scipy.optimize import minimize

    model = TransferFunctionModel()
    u0 = np.ravel(start_inputs).astype(float)
    stack = _impulse_sensitivities(model, np.asarray(theta, float), u0.size)

    def cost_and_gradient(u: np.ndarray) -> tuple[float, np.ndarray]:
        psi = np.einsum("pkj,j->kp", stack, u)
        inverse = np.linalg.inv(psi.T @ psi / noise_variance)
        weight = psi @ (inverse if criterion == "D" else -inverse @ inverse)
        gradient = 2.0 / noise_variance * np.einsum("pkj,kp->j", stack, weight)
        if criterion == "D":
            return -np.linalg.slogdet(psi.T @ psi / noise_variance)[1], -gradient
        return float(np.trace(inverse)), gradient

    difference = np.eye(u0.size) - np.eye(u0.size, k=-1)
    limits = [{"type": "ineq", "fun": lambda u, s=s: rate - s * (difference @ u),
               "jac": lambda u, s=s: -s * difference} for s in (1.0, -1.0)]
    start_cost = cost_and_gradient(u0)[0]
    result = minimize(cost_and_gradient, u0, jac=True, method="SLSQP",
                      bounds=[(-amplitude, amplitude)] * u0.size, constraints=limits,
                      options={"maxiter": max_iterations, "ftol": 1e-12})
    inputs = np.clip(result.x, -amplitude, amplitude)
    sign = -1.0 if criterion == "D" else 1.0
    return GradientDesign(inputs, sign * cost_and_gradient(inputs)[0], sign * start_cost,
                          bool(result.success), str(result.message), int(result.nit))


def _polished(model: TransferFunctionModel, offline: OfflineDesign,
              criterion: str) -> OfflineDesign:
    """`offline` with its inputs replaced by the best gradient optimum started from them and from
    the start input (if better; the criterion has local optima about 0.2 apart in log det)."""
    runs = [design_by_gradient(offline.theta, start[:, 0], criterion=criterion,
                               noise_variance=float(offline.noise_variance))
            for start in (offline.inputs, offline.start_inputs)]
    gradient = max(runs, key=lambda run: run.value if criterion == "D" else -run.value)
    better = gradient.value > offline.value if criterion == "D" else gradient.value < offline.value
    if not better:
        return replace(offline, message=offline.message + "; SLSQP polish found no better input")
    inputs = gradient.inputs[:, None]
    fisher = inputs_fisher_information(model, offline.theta, inputs, offline.noise_variance)
    return replace(offline, inputs=inputs, increments=np.diff(np.r_[[[0.0]], inputs], axis=0),
                   fisher=fisher, covariance=cramer_rao_covariance(fisher),
                   value=float(criterion_value(fisher, criterion)),
                   message=(f"{offline.message}; SLSQP polish {offline.value:.4f} -> "
                            f"{gradient.value:.4f} in {gradient.n_iterations} iterations"))


def run_thesis_example(*, end_time: float = END_TIME, criterion: str = "D",
                       offline_options: GeneticOptions = THESIS_OFFLINE_OPTIONS,
                       online_options: OnlineOptions = THESIS_ONLINE_OPTIONS, seed: int = 0,
                       polish: bool = True,
                       progress: Callable[[str], None] | None = None) -> ThesisExample:
    """The thesis' section 5.4 example: offline and online designs against the two-sine input.

    With `polish` (criteria A and D) the GA's best input is refined by
    :func:`design_by_gradient` on the same criterion (started from the GA's best and from the
    two-sine input, the better kept), so that the offline design reaches its optimum (the GA alone stops about 1.9 below the optimum's log det M for the 30 s example,
    and the online input then scores better than it on the offline criterion).
    """
    n_samples = round(end_time / SAMPLE_PERIOD)
    model = TransferFunctionModel()
    theta_true = discretise_oscillator(*TRUE_PHYSICAL)
    theta_initial = discretise_oscillator(*INITIAL_PHYSICAL)
    constraints = InputConstraints.symmetric(AMPLITUDE_LIMIT, RATE_LIMIT)
    sine = two_sine_input(n_samples, SAMPLE_PERIOD)
    offline = design_offline(model, theta_initial, sine, constraints,
                             options=OfflineOptions(criterion, NOISE_VARIANCE, offline_options),
                             progress=progress)
    if polish and criterion in ("A", "D"):
        offline = _polished(model, offline, criterion)
        if progress is not None:
            progress(f"offline DoE: gradient polish {offline.message}")
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
                "seed": seed, "polish": float(polish)}
    return ThesisExample(theta_true, theta_initial, offline, online, evaluations, settings)
