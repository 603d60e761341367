"""Fisher information, optimality criteria and the line example (thesis sections 5.2-5.3).

For outputs with independent Gaussian noise :math:`\\varepsilon \\sim N(0, \\sigma^2)` on a model
output :math:`y_m(t_k, \\theta)` (eq. 5.4), the Fisher information matrix is (eq. 5.6)

.. math:: M(\\theta) = \\sum_{k=1}^{N} \\sum_{j} \\frac{1}{\\sigma_j^2}
          \\psi_{kj} \\psi_{kj}^T, \\qquad \\psi_{kj} = \\partial y_{m,j}(t_k) / \\partial \\theta,

and its inverse is the Cramer-Rao lower bound on the covariance of any unbiased estimator
(eq. 5.1), reached by an efficient one (least squares on a model linear in its parameters).
A design maximises an information measure :math:`\\phi(M)` (eq. 5.3, section 5.2):

* A-optimality: minimise :math:`\\operatorname{tr} M^{-1}` (mean variance of the estimates),
* D-optimality: maximise :math:`\\det M`, here :math:`\\log\\det M` (numerically safe),
* E-optimality: maximise the smallest eigenvalue :math:`\\lambda_{\\min}(M)`.

Every function takes stacks: leading axes are candidates (e.g. a GA population), so one call
scores a whole population.

The line example (section 5.3): :math:`y = k x + d` measured at points :math:`x_i \\in [-1, 1]`
has :math:`\\psi_i = [x_i, 1]` and :math:`M = \\sigma^{-2} [[\\sum x_i^2, \\sum x_i],
[\\sum x_i, N]]`, :math:`\\det M = (x_1 - x_2)^2 / \\sigma^4` for two points: the D-optimal pair
is :math:`\\pm 1` with zero covariance between slope and intercept. For three points the third
goes to an end point (``det = 8 / sigma^4``); requiring zero covariance
(:math:`\\sum x_i = 0`) puts it at 0 (``det = 6 / sigma^4``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import LinearConstraint, minimize

Criterion = Literal["A", "D", "E"]
CRITERIA: tuple[str, ...] = ("A", "D", "E")


def fisher_information(sensitivities: np.ndarray,
                       noise_variance: float | np.ndarray) -> np.ndarray:
    """Fisher information matrix of eq. 5.6 from output sensitivities.

    Parameters
    ----------
    sensitivities : ndarray, shape (..., N, n_outputs, n_theta) or (N, n_theta)
        :math:`\\psi = \\partial \\hat y / \\partial \\theta` per sample and output. A 2-D array is
        one output; with three or more axes the last three are (N, n_outputs, n_theta) and any
        leading axes are candidates (a stack of designs).
    noise_variance : float or ndarray, shape (n_outputs,)
        :math:`\\sigma^2` per output [output unit squared].

    Returns
    -------
    ndarray, shape (..., n_theta, n_theta)
        :math:`M = \\sum_k \\sum_j \\psi_{kj} \\psi_{kj}^T / \\sigma_j^2`.
    """
    psi = np.asarray(sensitivities, float)
    if psi.ndim == 2:
        psi = psi[:, None, :]
    if psi.ndim < 3:
        raise ValueError(f"sensitivities need shape (N, n_theta) or (..., N, n_outputs, n_theta), "
                         f"got {psi.shape}")
    variance = np.broadcast_to(np.asarray(noise_variance, float), (psi.shape[-2],)) \
        if np.ndim(noise_variance) == 0 else np.asarray(noise_variance, float)
    if np.any(~np.isfinite(variance)) or np.any(variance <= 0):
        raise ValueError(f"noise_variance must be positive and finite, got {noise_variance!r}")
    if variance.shape != (psi.shape[-2],):
        raise ValueError(f"sensitivities of shape {psi.shape} ({psi.shape[-2]} outputs) do not "
                         f"match noise_variance of shape {variance.shape}")
    weighted = psi / variance[:, None]
    return np.einsum("...kji,...kjl->...il", weighted, psi)


def cramer_rao_covariance(fisher: np.ndarray) -> np.ndarray:
    """Cramer-Rao lower bound :math:`M^{-1}` on the parameter covariance (eq. 5.1).

    Raises ``numpy.linalg.LinAlgError`` for a singular (non-identifying) experiment.
    """
    fisher = np.asarray(fisher, float)
    symmetric = 0.5 * (fisher + np.swapaxes(fisher, -1, -2))
    return np.linalg.inv(symmetric)


def a_optimality(fisher: np.ndarray) -> np.ndarray | float:
    """A-criterion :math:`\\operatorname{tr} M^{-1}` (to minimise); inf where M is singular."""
    fisher = np.asarray(fisher, float)
    eigenvalues = np.linalg.eigvalsh(fisher)
    with np.errstate(divide="ignore"):
        inverse = np.where(eigenvalues > 0, 1.0 / np.where(eigenvalues > 0, eigenvalues, 1.0),
                           np.inf)
    return _scalar(inverse.sum(axis=-1))


def d_optimality(fisher: np.ndarray) -> np.ndarray | float:
    """D-criterion :math:`\\log\\det M` (to maximise); -inf where M is singular."""
    sign, logdet = np.linalg.slogdet(np.asarray(fisher, float))
    return _scalar(np.where(sign > 0, logdet, -np.inf))


def e_optimality(fisher: np.ndarray) -> np.ndarray | float:
    """E-criterion :math:`\\lambda_{\\min}(M)` (to maximise)."""
    return _scalar(np.linalg.eigvalsh(np.asarray(fisher, float))[..., 0])


def criterion_value(fisher: np.ndarray, criterion: str) -> np.ndarray | float:
    """The criterion as the thesis states it (A: trace of the inverse, D: log det, E: min eig)."""
    functions = {"A": a_optimality, "D": d_optimality, "E": e_optimality}
    if criterion not in functions:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    return functions[criterion](fisher)


def criterion_cost(fisher: np.ndarray, criterion: str) -> np.ndarray | float:
    """The criterion as a cost to minimise (eq. 5.3): tr M^-1, -log det M or -lambda_min(M)."""
    value = criterion_value(fisher, criterion)
    return value if criterion == "A" else -value


def _scalar(value: np.ndarray) -> np.ndarray | float:
    return float(value) if np.ndim(value) == 0 else value


# --- the line example (section 5.3) ---------------------------------------------------------

def line_sensitivities(points: np.ndarray) -> np.ndarray:
    """Sensitivities :math:`[x_i, 1]` of :math:`y = k x + d` to (k, d), shape (..., N, 2)."""
    x = np.asarray(points, float)
    return np.stack([x, np.ones_like(x)], axis=-1)


def line_fisher_closed_form(points: np.ndarray, noise_variance: float) -> np.ndarray:
    """:math:`M = \\sigma^{-2} [[\\sum x^2, \\sum x], [\\sum x, N]]` written out (section 5.3)."""
    x = np.asarray(points, float)
    return np.array([[np.sum(x ** 2), np.sum(x)], [np.sum(x), float(x.size)]]) / noise_variance


@dataclass(frozen=True)
class LineDesign:
    """A measurement-point design for the line :math:`y = k x + d`.

    Parameters
    ----------
    points : ndarray, shape (N,)
        Designed positions, sorted.
    fisher : ndarray, shape (2, 2)
    covariance : ndarray, shape (2, 2)
        Cramer-Rao covariance of (slope, intercept).
    criterion : str
    value : float
        Criterion value (A: tr M^-1, D: log det M, E: lambda_min).
    zero_covariance : bool
        Whether cov(slope, intercept) = 0 was imposed.
    success : bool
    """

    points: np.ndarray
    fisher: np.ndarray
    covariance: np.ndarray
    criterion: str
    value: float
    zero_covariance: bool
    success: bool


def design_line_experiment(n_points: int, *, criterion: str = "D",
                           interval: tuple[float, float] = (-1.0, 1.0),
                           noise_variance: float = 1.0, zero_covariance: bool = False,
                           n_starts: int = 20,
                           rng: np.random.Generator | None = None) -> LineDesign:
    """Optimal measurement points for slope and intercept of a line (section 5.3).

    Maximises the criterion over :math:`x \\in [a, b]^N` by SLSQP from `n_starts` random starts
    (the problem is non-convex: the points may be permuted and mirrored). With
    ``zero_covariance`` the linear constraint :math:`\\sum x_i = 0` makes the off-diagonal of
    :math:`M^{-1}` (:math:`\\propto -\\sum x_i`) vanish.
    """
    if n_points < 2:
        raise ValueError(f"n_points must be at least 2 to identify slope and intercept, got {n_points}")
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    low, high = map(float, interval)
    if not high > low:
        raise ValueError(f"interval must be (low, high) with high > low, got {interval!r}")
    rng = np.random.default_rng(0) if rng is None else rng
    constraints = [LinearConstraint(np.ones((1, n_points)), 0.0, 0.0)] if zero_covariance else []

    def cost(x: np.ndarray) -> float:
        fisher = fisher_information(line_sensitivities(x), noise_variance)
        value = criterion_cost(fisher + 1e-12 * np.eye(2) / noise_variance, criterion)
        return float(value) if np.isfinite(value) else 1e12

    best = None
    for _ in range(n_starts):
        start = rng.uniform(low, high, n_points)
        if zero_covariance:
            start -= start.mean()
        result = minimize(cost, start, method="SLSQP", bounds=[(low, high)] * n_points,
                          constraints=constraints, options={"ftol": 1e-12, "maxiter": 200})
        if best is None or (result.success and result.fun < best.fun) or not best.success:
            best = result
    points = np.sort(np.clip(best.x, low, high))
    fisher = fisher_information(line_sensitivities(points), noise_variance)
    return LineDesign(points, fisher, cramer_rao_covariance(fisher), criterion,
                      float(criterion_value(fisher, criterion)), zero_covariance,
                      bool(best.success))
