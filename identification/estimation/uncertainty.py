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
    the reason. The Fisher information is the square of the noise-weighted sensitivity (the
    Jacobian in ``z``, each output's rows divided by its residual standard deviation), so its
    eigenvalues are the squared singular values of that scaled sensitivity.

Verdicts (:class:`ParameterEstimate`)
    Every fitted parameter gets one of

    - *not identifiable*: relative standard deviation ``sigma_z`` above the threshold (0.5,
      i.e. 50 %), or a member of a direction along which the standard deviation exceeds it;
    - *weakly identifiable*: ``sigma_z`` above a fifth of the threshold (10 %), or a member of a
      direction whose singular value is below :data:`WEAK_SINGULAR_RATIO` (1e-3) of the largest
      (an ill-conditioned trade-off, even if the noise is low);
    - *identifiable*: neither;
    - *at bound*: the estimate sits at its lower or upper bound. Its column is left out of the
      covariance (the bound is an active constraint: the others' uncertainty is conditional on
      it) and it gets no symmetric interval (standard deviation NaN).

    Correlated groups: parameters whose estimates correlate with ``|rho| >`` :data:`GROUP_CORRELATION`
    (0.95), joined transitively. 95 % intervals: ``theta exp(+-1.96 sigma_z)`` for the
    log-parameterised (positive lower bound, so the interval never crosses zero) and
    ``theta +- 1.96 sigma`` for the others.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

#: z-value of the two-sided 95 % normal interval.
Z95 = 1.959963984540054
#: Fraction of the threshold on the relative standard deviation above which a parameter is only
#: weakly identifiable (0.2 of 0.5: 10 %).
WEAK_FRACTION = 0.2
#: Singular value of the scaled sensitivity, relative to the largest, below which the parameters
#: of that direction are (at most) weakly identifiable.
WEAK_SINGULAR_RATIO = 1e-3
#: |correlation| above which two parameters are reported in one correlated group.
GROUP_CORRELATION = 0.95
#: What the verdicts mean, stated in every report.
RULE = ("not identifiable: relative standard deviation > {t:g} or member (component >= 0.3) of a "
        "direction with standard deviation > {t:g} along it; weakly identifiable: relative standard "
        "deviation > {w:g} or member of a direction whose singular value of the noise-weighted "
        "sensitivity (Jacobian in z) is < {r:g} of the largest; at bound: the estimate sits at a "
        "bound (no symmetric interval); groups: |correlation| > {g:g}")


@dataclass(frozen=True)
class ParameterEstimate:
    """One fitted parameter as a report shows it.

    Attributes
    ----------
    name : str
    value : float
        Estimate (the prior when `fixed`), in `unit`.
    unit : str
        From the structure's ``units()``, ``"-"`` when it has none.
    std : float
        Standard deviation [unit]; NaN at a bound or when fixed.
    relative_std : float
        ``sigma_z``: standard deviation of ``ln theta`` (log-parameterised) or ``sigma / |theta|``.
    interval_95 : tuple of float
        ``theta exp(+-1.96 sigma_z)`` (log-parameterised) or ``theta +- 1.96 sigma``; NaN at a
        bound or when fixed.
    logarithmic : bool
        Optimised as ``z = ln(theta / theta_0)`` (positive lower bound).
    verdict : str
        ``"identifiable"``, ``"weakly identifiable"``, ``"not identifiable"`` or ``"at bound"``.
    at_bound : str or None
        ``"lower"``, ``"upper"`` or None.
    fixed : bool
        Fixed at its prior after the first fit found it not identifiable.
    group : tuple of str
        The correlated group it belongs to (``|rho| >`` :data:`GROUP_CORRELATION`), itself
        included; empty when alone.
    reason : str
        Why the verdict (empty for identifiable).
    """

    name: str
    value: float
    unit: str = "-"
    std: float = math.nan
    relative_std: float = math.nan
    interval_95: tuple[float, float] = (math.nan, math.nan)
    logarithmic: bool = False
    verdict: str = "identifiable"
    at_bound: str | None = None
    fixed: bool = False
    group: tuple[str, ...] = ()
    reason: str = ""

    @property
    def status(self) -> str:
        """``"estimated"``, ``"at lower bound"``, ``"at upper bound"`` or ``"fixed at prior (not
        identifiable from this run)"``."""
        if self.fixed:
            return "fixed at prior (not identifiable from this run)"
        return f"at {self.at_bound} bound" if self.at_bound else "estimated"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as None)."""
        def plain(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"name": self.name, "value": self.value, "unit": self.unit, "std": plain(self.std),
                "relative_std": plain(self.relative_std),
                "interval_95": [plain(x) for x in self.interval_95],
                "logarithmic": self.logarithmic, "verdict": self.verdict,
                "at_bound": self.at_bound, "fixed": self.fixed, "status": self.status,
                "group": list(self.group), "reason": self.reason}


def uncertainty(problem: Any, z: np.ndarray, r: np.ndarray, jac: np.ndarray,
                threshold: float = 0.5, active: np.ndarray | None = None) -> dict[str, Any]:
    """Covariance (physical units), standard deviations and identifiability (module notes).

    `active` (boolean per free parameter, default all) marks the parameters not held at a
    bound: only their columns enter the covariance; the others get NaN rows and columns. The
    identifiability is judged on every column (whether the data pin a parameter does not depend
    on where the fit left it).
    """
    parts = problem.split(r)
    n_free = len(z)
    active = np.ones(n_free, bool) if active is None else np.asarray(active, bool)
    variances = []
    for part in parts:
        dof = max(1.0, len(part) - n_free * len(part) / len(r))
        variances.append(float(part @ part) / dof)
    weights = np.concatenate([np.full(len(p), v) for p, v in zip(parts, variances)])
    cov_all, s = _sandwich(jac, parts, variances)
    cov_z = cov_all
    if not active.all():
        cov_z = np.full((n_free, n_free), np.nan)
        cov_z[np.ix_(active, active)] = _sandwich(jac[:, active], parts, variances)[0]
    derivative = problem.derivative(z)
    covariance = cov_z * np.outer(derivative, derivative)
    std_z = np.sqrt(np.clip(np.diag(cov_z), 0.0, None))
    fisher = jac.T @ (jac / weights[:, None])
    identifiability = describe_identifiability(problem.free, fisher, std_z, s, threshold)
    if not active.all():  # verdicts consistent with the intervals shown; at a bound: all columns
        inner = [n for n, a in zip(problem.free, active) if a]
        identifiability = _merge_reports(
            problem.free, describe_identifiability(inner, fisher[np.ix_(active, active)],
                                                   std_z[active], s, threshold),
            describe_identifiability(problem.free, fisher, np.sqrt(np.clip(
                np.diag(cov_all), 0.0, None)), s, threshold), active)
    noise = {name: math.sqrt(v) * spread for name, v, spread in
             zip(problem.data.output_names, variances, problem.spreads)}
    return {"covariance": covariance, "std": np.sqrt(np.clip(np.diag(covariance), 0.0, None)),
            "relative_std": std_z, "covariance_z": cov_z, "fisher": fisher,
            "identifiability": identifiability,
            "residual_std": noise}


def _merge_reports(free: Sequence[str], inner: dict[str, Any], whole: dict[str, Any],
                   active: np.ndarray) -> dict[str, Any]:
    """The report on the columns not at a bound, with the verdicts on the parameters at a bound
    taken from the report on every column."""
    held = [n for n, a in zip(free, active) if not a]
    merged = dict(inner)
    for key in ("not_identifiable", "weakly_identifiable"):
        merged[key] = {**inner[key], **{n: why for n, why in whole[key].items() if n in held}}
    merged["identifiable"] = [n for n in free if n not in merged["not_identifiable"]]
    merged["at_bound"] = held
    merged["fisher_eigenvalues_all_columns"] = whole["fisher_eigenvalues"]
    return merged


def _sandwich(jac: np.ndarray, parts: Sequence[np.ndarray], variances: Sequence[float]
              ) -> tuple[np.ndarray, np.ndarray]:
    """Sandwich covariance in ``z`` (module notes) and the singular values of `jac`.

    A parameter in a direction along which the outputs do not change at all (singular value
    below 1e-7.5 of the largest) gets an infinite variance; one without any influence NaN.
    """
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
    # directions the pseudo-inverse drops (the outputs do not change along them): unbounded
    # variance for the parameters taking part (component >= 0.1 of the largest)
    for vector in vectors[:, ~kept].T:
        members = np.abs(vector) >= 0.1 * np.max(np.abs(vector))
        cov_z[np.ix_(members, members)] = np.inf  # correlation +-1 among them in the limit
    dead = ~np.any(jac != 0.0, axis=0)  # a parameter without any influence
    cov_z[:, dead] = np.nan
    cov_z[dead, :] = np.nan
    return cov_z, s


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
    """Weak directions of the Fisher information and the parameters that are not identifiable.

    Parameters
    ----------
    free : sequence of str
    fisher : ndarray, shape (n, n)
        ``J_w^T J_w`` of the noise-weighted sensitivity ``J_w`` in ``z`` (module notes).
    std_z : ndarray, shape (n,)
        Relative standard deviations (NaN or inf: no influence).
    singular_values : ndarray
        Singular values of the unweighted Jacobian (reported only).
    threshold : float
        Relative standard deviation above which a parameter (or direction) is not identifiable;
        a fifth of it (:data:`WEAK_FRACTION`) makes it weakly identifiable.

    Returns
    -------
    dict
        ``not_identifiable`` and ``weakly_identifiable`` (name -> reason), ``identifiable``
        (every name not in ``not_identifiable``, the weak ones included), ``weak_directions``,
        ``rule`` (the thresholds in words) and the spectra.
    """
    eigenvalues, vectors = np.linalg.eigh(0.5 * (fisher + fisher.T))
    largest = max(float(np.max(eigenvalues)), 0.0) if eigenvalues.size else 0.0
    weak = []
    reasons: dict[str, list[str]] = {}
    weakly: dict[str, list[str]] = {}
    for lam, vector in zip(eigenvalues, vectors.T):
        spread = math.inf if lam <= 0 else 1.0 / math.sqrt(lam)
        ratio = math.sqrt(lam / largest) if lam > 0 and largest > 0 else 0.0
        if spread <= threshold and ratio >= WEAK_SINGULAR_RATIO:
            continue
        vector = vector / np.max(np.abs(vector)) * np.sign(vector[np.argmax(np.abs(vector))])
        members = {name: round(float(c), 3) for name, c in zip(free, vector) if abs(c) >= 0.3}
        weak.append({"std_along": spread, "relative_singular_value": ratio,
                     "components": members, "not_identifiable": spread > threshold})
        for name in members:
            others = [m for m in members if m != name]
            traded = f", traded off against {', '.join(others)}" if others else ""
            if spread > threshold:
                reasons.setdefault(name, []).append(
                    f"in a near-null direction of the Fisher information (std {spread:.3g} in "
                    "relative units along it)" + traded)
            else:
                weakly.setdefault(name, []).append(
                    f"in an ill-conditioned direction (singular value {ratio:.2g} of the largest "
                    f"< {WEAK_SINGULAR_RATIO:g})" + traded)
    for name, sz in zip(free, std_z):
        if math.isnan(sz):
            reasons.setdefault(name, []).insert(0, "the outputs do not depend on it (zero "
                                                "Jacobian column)")
        elif math.isinf(sz):
            reasons.setdefault(name, []).insert(0, "relative standard deviation unbounded (a "
                                                "direction the outputs do not change along)")
        elif sz > threshold:
            reasons.setdefault(name, []).insert(0, f"relative standard deviation {sz:.3g} > "
                                                f"{threshold:g}")
        elif sz > WEAK_FRACTION * threshold:
            weakly.setdefault(name, []).insert(0, f"relative standard deviation {sz:.3g} > "
                                               f"{WEAK_FRACTION * threshold:g}")
    relative = singular_values / singular_values[0] if singular_values.size and \
        singular_values[0] > 0 else singular_values
    return {
        "threshold_relative_std": threshold,
        "threshold_weak_relative_std": WEAK_FRACTION * threshold,
        "threshold_singular_value_ratio": WEAK_SINGULAR_RATIO,
        "rule": RULE.format(t=threshold, w=WEAK_FRACTION * threshold, r=WEAK_SINGULAR_RATIO,
                            g=GROUP_CORRELATION),
        "singular_values": singular_values.tolist(),
        "relative_singular_values": relative.tolist(),
        "condition_number": float(relative[0] / relative[-1]) if relative.size and
        relative[-1] > 0 else math.inf,
        "fisher_eigenvalues": eigenvalues.tolist(),
        "weak_directions": weak,
        "not_identifiable": {name: "; ".join(r) for name, r in reasons.items()},
        "weakly_identifiable": {name: "; ".join(r) for name, r in weakly.items()
                                if name not in reasons},
        "identifiable": [n for n in free if n not in reasons],
    }


def correlated_groups(free: Sequence[str], cov_z: np.ndarray,
                      limit: float = GROUP_CORRELATION) -> list[tuple[str, ...]]:
    """Groups of parameters whose estimates correlate with ``|rho| > limit``, joined
    transitively (parameters with a NaN variance take part in none).

    >>> correlated_groups("abc", np.array([[1, .99, 0], [.99, 1, 0], [0, 0, 1]]))
    [('a', 'b')]
    """
    d = np.sqrt(np.abs(np.diag(cov_z)))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = cov_z / np.outer(d, d)
    linked = np.nan_to_num(np.abs(rho), nan=0.0, posinf=0.0) > limit
    unbounded = np.isinf(cov_z)  # members of one null direction: correlation +-1 in the limit
    np.fill_diagonal(unbounded, False)
    linked |= unbounded
    label = list(range(len(free)))
    for i in range(len(free)):
        for j in range(i + 1, len(free)):
            if linked[i, j] and label[j] != label[i]:
                old = label[j]
                label = [label[i] if x == old else x for x in label]
    groups: dict[int, list[str]] = {}
    for name, k in zip(free, label):
        groups.setdefault(k, []).append(name)
    return [tuple(g) for g in groups.values() if len(g) > 1]


def _log_interval(theta: float, half: float) -> tuple[float, float]:
    """``theta exp(-half) .. theta exp(half)``; 0 and infinity where that leaves the floats."""
    with np.errstate(over="ignore", under="ignore"):
        return float(theta * np.exp(-half)), float(theta * np.exp(half))


def parameter_estimates(problem: Any, z: np.ndarray, info: Mapping[str, Any],
                        at_bound: Mapping[str, str], units: Mapping[str, str]
                        ) -> dict[str, ParameterEstimate]:
    """One :class:`ParameterEstimate` per free parameter of `problem` at `z` (module notes).

    `info` is what :func:`uncertainty` returned, `at_bound` names the parameters at a bound
    (``"lower"``/``"upper"``), `units` the unit per parameter (``"-"`` when absent).
    """
    theta = problem.theta(z)
    std = np.asarray(info["std"], float)
    std_z = np.asarray(info["relative_std"], float)
    report = info["identifiability"]
    groups = {n: g for g in correlated_groups(problem.free, info["covariance_z"]) for n in g}
    out = {}
    for k, name in enumerate(problem.free):
        log = bool(problem.logarithmic[k])
        relative = std_z[k] if log else std[k] / abs(theta[k]) if theta[k] else math.inf
        half = Z95 * std_z[k] if log else Z95 * std[k]
        interval = _log_interval(theta[k], half) if log else (theta[k] - half, theta[k] + half)
        verdict, reason = _verdict(name, report)
        side = at_bound.get(name)
        if side:
            reason = (f"at its {side} bound {theta[k]:.4g} {units.get(name, '-')}: no symmetric "
                      "interval" + (f" (and not identifiable: {reason})" if verdict ==
                                    "not identifiable" else ""))
            verdict, interval, std_k = "at bound", (math.nan, math.nan), math.nan
        else:
            std_k = float(std[k])
        out[name] = ParameterEstimate(
            name, float(theta[k]), units.get(name, "-"), std_k,
            float(relative) if not side else math.nan,
            (float(interval[0]), float(interval[1])), log, verdict, side, False,
            groups.get(name, ()), reason)
    return out


def _verdict(name: str, report: Mapping[str, Any]) -> tuple[str, str]:
    """The verdict and its reason from :func:`describe_identifiability`'s report."""
    if name in report["not_identifiable"]:
        return "not identifiable", report["not_identifiable"][name]
    if name in report.get("weakly_identifiable", {}):
        return "weakly identifiable", report["weakly_identifiable"][name]
    return "identifiable", ""


def parameters_to_fix(free: Sequence[str], fisher: np.ndarray, threshold: float,
                      candidates: Sequence[str]) -> list[str]:
    """The fewest of the not-identifiable `candidates` whose fixing removes the weak directions.

    Every candidate the outputs do not depend on (zero row of `fisher`); then, with ``V`` the
    ``k`` eigenvectors of the Fisher information along which the standard deviation exceeds
    `threshold`, the ``k`` parameters a column-pivoted QR of ``V^T`` picks (the subset selection
    of Golub, Klema and Stewart: the rows of ``V`` closest to a basis of the weak subspace). The
    other members of a direction stay free: fixing one of two parameters that enter only as a
    product leaves the product identifiable. When that picks none, the candidate of largest
    variance ``diag(F^+)``. Repeated after each refit until no candidate is left
    (:func:`panto.identification.estimation.least_squares.fit_least_squares`).

    >>> parameters_to_fix("ab", np.full((2, 2), 100.0), 0.5, ["a", "b"])
    ['a']
    """
    from scipy.linalg import qr

    fisher = 0.5 * (fisher + fisher.T)
    dead = [n for n, column in zip(free, fisher.T) if not np.any(column)]
    alive = [k for k, n in enumerate(free) if n not in dead]
    chosen = list(dead)
    if alive:
        sub = fisher[np.ix_(alive, alive)]
        eigenvalues, vectors = np.linalg.eigh(sub)
        weak = vectors[:, eigenvalues * threshold ** 2 < 1.0]
        if weak.shape[1]:
            pivots = qr(weak.T, pivoting=True, mode="r")[1]
            chosen += [free[alive[k]] for k in pivots[:weak.shape[1]]]
    chosen = [n for n in chosen if n in candidates]
    if not chosen and candidates:
        variance = dict(zip(free, np.diag(np.linalg.pinv(fisher))))
        chosen.append(max(candidates, key=lambda n: variance[n]))
    return chosen
