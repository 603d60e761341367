"""Uncertainty and identifiability of a least-squares estimate (used by :mod:`least_squares`).

Covariance
    With ``J`` the Jacobian of the normalised residuals ``r`` in the transformed parameters ``z``
    and ``s_j^2`` the residual variance of output ``j`` (in units of ``r``, degrees of freedom
    shared out), the covariance of the estimate is the sandwich
    ``(J^T J)^-1 J^T S J (J^T J)^-1`` (the fit's weights are not ``1/s_j^2``), mapped to
    physical units with ``d theta / d z``. Exact for white noise; a free-run residual coloured by
    model error makes it optimistic.

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
    middle = jac.T @ (jac * weights[:, None])
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
