"""Uncertainty and identifiability of a least-squares estimate (used by :mod:`least_squares`).

Covariance
    With ``J`` the Jacobian of the normalised residuals ``r`` in the transformed parameters ``z``
    and ``s_j^2`` the residual variance of output ``j`` (in units of ``r``, degrees of freedom
    shared out), the covariance of the estimate is the sandwich
    ``(J^T J)^-1 J^T S J (J^T J)^-1`` (the fit's weights are not ``1/s_j^2``), mapped to
    physical units with ``d theta / d z``. ``S`` is not taken as white: each output's residual
    autocovariance, tapered by a Bartlett window (:func:`residual_autocovariance`), fills a
    Toeplitz ``S``, so noise coloured by the anti-alias low-pass of a resampled record (20 Hz
    stopband at 100 or 250 Hz) widens the intervals as it should. With white noise this is the
    usual ``s_j^2 (J^T J)^-1``; a residual coloured by model error still leaves it somewhat
    optimistic (the taper cuts the long lags).

Identifiability
    The Fisher information ``F = sum_j J_j^T J_j / s_j^2`` in the relative parameters: its
    eigenvectors whose standard deviation ``1 / sqrt(lambda)`` exceeds the threshold are
    directions the data cannot pin down; the parameters taking part in them (component >= 0.3 of
    the largest), or whose own relative standard deviation exceeds the threshold, are named with
    the reason.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np


def uncertainty(problem: Any, z: np.ndarray, r: np.ndarray, jac: np.ndarray,
                threshold: float = 0.5) -> dict[str, Any]:
    """Covariance (physical units), standard deviations and identifiability (module notes)."""
    parts = problem.split(r)
    n_free = len(z)
    variances = []
    for part in parts:
        dof = max(1.0, len(part) - n_free * len(part) / len(r))
        variances.append(float(part @ part) / dof)
    weights = np.concatenate([np.full(len(p), v) for p, v in zip(parts, variances)])
    eigenvalues, vectors = np.linalg.eigh(jac.T @ jac)  # J^T J = V S^2 V^T (no big SVD)
    order = np.argsort(eigenvalues)[::-1]
    eigenvalues, vectors = np.clip(eigenvalues[order], 0.0, None), vectors[:, order]
    s = np.sqrt(eigenvalues)
    kept = eigenvalues > eigenvalues[0] * 1e-15 if s.size and s[0] > 0 else np.zeros_like(s, bool)
    inverse = (vectors[:, kept] / eigenvalues[kept]) @ vectors[:, kept].T  # (J^T J)^+
    bounds = np.cumsum([0] + [len(part) for part in parts])
    middle = np.zeros_like(inverse)
    for a, b, part, variance in zip(bounds[:-1], bounds[1:], parts, variances):
        gamma = residual_autocovariance(part)  # its shape; the level is the variance's
        middle += _coloured_product(jac[a:b], gamma * (variance / gamma[0] if gamma[0] > 0 else 0))
    cov_z = inverse @ middle @ inverse
    cov_z[:, ~np.any(jac != 0.0, axis=0)] = np.nan  # a parameter without any influence
    cov_z[~np.any(jac != 0.0, axis=0), :] = np.nan
    derivative = problem.derivative(z)
    covariance = cov_z * np.outer(derivative, derivative)
    std_z = np.sqrt(np.clip(np.diag(cov_z), 0.0, None))
    fisher = jac.T @ (jac / weights[:, None])
    identifiability = describe_identifiability(problem.free, fisher, std_z, s, threshold)
    noise = {name: math.sqrt(v) * spread for name, v, spread in
             zip(problem.data.output_names, variances, problem.spreads)}
    return {"covariance": covariance, "std": np.sqrt(np.clip(np.diag(covariance), 0.0, None)),
            "relative_std": std_z, "identifiability": identifiability, "residual_std": noise}


def residual_autocovariance(residual: np.ndarray, max_lag: int | None = None) -> np.ndarray:
    """Tapered autocovariance ``gamma(0..L)`` of a residual, for the noise covariance ``S``.

    ``L`` is twice the first lag at which the sample autocorrelation falls inside its white-noise
    band ``+-2/sqrt(n)`` (at least 1, at most ``n/10`` or `max_lag`), and ``gamma(l)`` is
    weighted by the Bartlett window ``1 - l/(L+1)``, which keeps ``S`` positive semi-definite.
    The mean is removed first.

    >>> g = residual_autocovariance(np.random.default_rng(0).standard_normal(4000))
    >>> round(float(g[0]), 1), len(g) <= 3
    (1.0, True)
    """
    e = np.asarray(residual, float)
    e = e - e.mean()
    n = len(e)
    if n < 8 or not np.any(e):
        return np.array([float(e @ e) / max(n, 1)])
    limit = max(1, min(n // 10, max_lag if max_lag is not None else n))
    spectrum = np.fft.rfft(e, 2 * n)
    acov = np.fft.irfft(spectrum * np.conj(spectrum))[:limit + 1] / n
    rho = acov / acov[0]
    inside = np.nonzero(np.abs(rho[1:]) < 2.0 / math.sqrt(n))[0]
    first = int(inside[0]) + 1 if inside.size else limit
    lags = min(limit, 2 * first)
    taper = 1.0 - np.arange(lags + 1) / (lags + 1)
    return acov[:lags + 1] * taper


def _coloured_product(jac: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """``J^T S J`` for the Toeplitz noise covariance ``S`` of autocovariance `gamma`."""
    product = gamma[0] * (jac.T @ jac)
    for lag in range(1, min(len(gamma), len(jac))):
        cross = jac[:-lag].T @ jac[lag:]
        product += gamma[lag] * (cross + cross.T)
    return product


def describe_identifiability(free: Sequence[str], fisher: np.ndarray, std_z: np.ndarray,
                             singular_values: np.ndarray, threshold: float) -> dict[str, Any]:
    """Weak directions of the Fisher information and the parameters that are not identifiable."""
    eigenvalues, vectors = np.linalg.eigh(0.5 * (fisher + fisher.T))
    weak = []
    reasons: dict[str, list[str]] = {}
    for lam, vector in zip(eigenvalues, vectors.T):
        spread = math.inf if lam <= 0 else 1.0 / math.sqrt(lam)
        if spread <= threshold:
            continue
        vector = vector / np.max(np.abs(vector)) * np.sign(vector[np.argmax(np.abs(vector))])
        members = {name: round(float(c), 3) for name, c in zip(free, vector) if abs(c) >= 0.3}
        weak.append({"std_along": spread, "components": members})
        for name in members:
            others = [m for m in members if m != name]
            reasons.setdefault(name, []).append(
                f"in a near-null direction of the Fisher information (std {spread:.3g} in relative "
                "units along it)" + (f", traded off against {', '.join(others)}" if others else ""))
    for name, sz in zip(free, std_z):
        if not math.isfinite(sz):
            reasons.setdefault(name, []).insert(0, "the outputs do not depend on it (zero "
                                                "Jacobian column)")
        elif sz > threshold:
            reasons.setdefault(name, []).insert(0, f"relative standard deviation {sz:.3g} > "
                                                f"{threshold:g}")
    relative = singular_values / singular_values[0] if singular_values.size and \
        singular_values[0] > 0 else singular_values
    return {
        "threshold_relative_std": threshold,
        "singular_values": singular_values.tolist(),
        "relative_singular_values": relative.tolist(),
        "condition_number": float(relative[0] / relative[-1]) if relative.size and
        relative[-1] > 0 else math.inf,
        "fisher_eigenvalues": eigenvalues.tolist(),
        "weak_directions": weak,
        "not_identifiable": {name: "; ".join(r) for name, r in reasons.items()},
        "identifiable": [n for n in free if n not in reasons],
    }
