"""Where the gap lies: statistical analysis of a free-run residual (the diagnosis' first question).

Works on plain arrays of any system: inputs ``u`` (N, n_u), measured outputs ``y`` (N, n_y), the
nominal model's free-run simulation ``y_hat`` and the sample period. The residual is
``eps = y - y_hat`` (free run, as in MATLAB ``compare``/``resid``; thesis section 4.1.3).

Tests and their bounds (``z = 2.58``: 99 %):

- Whiteness: ``r(tau) = R_eps(tau) / R_eps(0)``, per-lag bound ``z / sqrt(N)``; portmanteau
  ``Q = N (N + 2) sum_{tau=1..M} r(tau)^2 / (N - tau) ~ chi2(M)`` (Ljung-Box).
- Independence from the inputs: ``r_eps_u(tau) = R_eps_u(tau) / sqrt(R_eps(0) R_u(0))`` with
  ``R_eps_u(tau) = 1/N sum_t eps(t) u(t - tau)`` for ``tau = -M..M`` and the bound
  ``z sqrt(P / N)``, ``P = sum_k r_eps(k) r_u(k)`` (Bartlett; Ljung, *System Identification*, 1999,
  section 16.6). A sharp peak at ``tau = d > 0`` hints a missing delay, a one-sided decaying band a
  missing lag, significant negative lags feedback.
- Model error model (Ljung): an ARX/FIR ``A(q) eps = sum_i B_i(q) u_i + e`` fitted by least squares;
  ``G_e = B_i / A`` with a band from the parameter covariance (delta method); where ``|G_e|`` leaves
  the band the nominal model is falsified; ``|G_e / G|`` is the relative error when ``G`` is given.
- Residual energy per frequency band (Welch), per time segment and per operating condition
  (:mod:`panto.identification.diagnosis.residual_energy`).
- Even/odd nonlinearity (Billings & Voon, 1986): correlation of ``eps`` with ``u^2 - mean``,
  ``y_hat^2`` and ``y_hat^3`` (each made orthogonal to the constant and the linear signal).
- Multisine detection lines (Pintelon & Schoukens, *System Identification*, 2012, chapter 4): power
  at unexcited odd and even lines against the noise level from the period-to-period spread.

Plots of these results: :mod:`panto.identification.diagnosis.residual_plots`.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps
from scipy import stats

from panto.identification.estimation.base import IdentificationData, IdentificationError, fit_percent
from panto.identification.diagnosis.residual_energy import (BandEnergy, ConditionEnergy,
                                                             SegmentEnergy, Serialisable,
                                                             energy_by_band, energy_by_condition,
                                                             energy_by_segment, energy_by_velocity,
                                                             finite_column, jsonable)

Z_99 = 2.58


def _matrix(x: np.ndarray, n: int, name: str) -> np.ndarray:
    x = np.asarray(x, float)
    x = x.reshape(n, -1) if x.size else np.zeros((n, 0))
    if x.shape[0] != n or not np.all(np.isfinite(x)):
        raise IdentificationError(f"{name}: need {n} finite rows, got shape {x.shape}")
    return x


def cross_correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised ``r_ab(tau) = sum_t a~(t) b~(t - tau) / (N sigma_a sigma_b)``, ``tau = -M..M``.

    ``a~, b~`` are the mean-removed signals; a lag ``tau > 0`` means ``b`` leads ``a``.
    """
    a = np.asarray(a, float) - np.mean(a)
    b = np.asarray(b, float) - np.mean(b)
    n = len(a)
    size = 1 << int(np.ceil(np.log2(2 * n)))
    full = np.fft.irfft(np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size)), size)
    lags = np.arange(-max_lag, max_lag + 1)
    scale = n * np.std(a) * np.std(b)
    values = full[lags % size] / scale if scale > 0 else np.zeros(len(lags))
    return lags, values


def correlation_bound(a: np.ndarray, b: np.ndarray, max_lag: int, z: float = Z_99) -> float:
    """Bound ``z sqrt(P / N)``, ``P = sum_{|k| <= M} r_a(k) r_b(k)`` for independent a, b."""
    _, ra = cross_correlation(a, a, max_lag)
    _, rb = cross_correlation(b, b, max_lag)
    return z * math.sqrt(max(float(np.sum(ra * rb)), 1.0) / len(a))


@dataclass(frozen=True)
class WhitenessTest(Serialisable):
    """Autocorrelation of a residual: ``r(tau)``, its bound and the portmanteau test."""

    lags: np.ndarray
    autocorrelation: np.ndarray
    bound: float
    q_statistic: float
    p_value: float
    n_outside: int
    white: bool


def check_whiteness(residual: np.ndarray, max_lag: int = 25, *, z: float = Z_99) -> WhitenessTest:
    """Whiteness of ``residual`` for lags 1..`max_lag` (bound ``z / sqrt(N)``, Ljung-Box Q).

    ``white`` holds when the portmanteau p-value exceeds the two-sided tail of `z` (1 % for 2.58).
    """
    eps = finite_column(residual, "residual")
    n = len(eps)
    lags, r = cross_correlation(eps, eps, max_lag)
    lags, r = lags[max_lag + 1:], r[max_lag + 1:]
    q = float(n * (n + 2) * np.sum(r ** 2 / (n - lags)))
    p = float(stats.chi2.sf(q, max_lag))
    bound = z / math.sqrt(n)
    alpha = 2 * stats.norm.sf(z)
    return WhitenessTest(lags, r, bound, q, p, int(np.sum(np.abs(r) > bound)), p > alpha)


@dataclass(frozen=True)
class CrossCorrelationTest(Serialisable):
    """Input-residual cross-correlation ``r_eps_u(tau)``, its bound and what its shape hints."""

    input_name: str
    lags: np.ndarray
    correlation: np.ndarray
    bound: float
    peak_lag: int
    peak_value: float
    positive_peak_lag: int
    """Lag > 0 of the largest ``|r|`` among positive lags (a missing delay's lag)."""
    independent: bool
    hints: tuple[str, ...]


def check_cross_correlation(residual: np.ndarray, u: np.ndarray, max_lag: int = 25, *,
                            z: float = Z_99, input_name: str = "u",
                            sample_period: float = 1.0) -> CrossCorrelationTest:
    """Cross-correlation of the residual with one input over ``tau = -M..M`` and its reading."""
    eps, u = finite_column(residual, "residual"), finite_column(u, input_name)
    lags, r = cross_correlation(eps, u, max_lag)
    bound = correlation_bound(eps, u, max_lag, z)
    peak = int(np.argmax(np.abs(r)))
    outside = np.abs(r) > bound
    positive = int(np.argmax(np.abs(r[lags > 0]))) + 1
    return CrossCorrelationTest(input_name, lags, r, bound, int(lags[peak]), float(r[peak]),
                                positive, not outside.any(),
                                _hints(lags, r, outside, bound, sample_period))


def _hints(lags: np.ndarray, r: np.ndarray, outside: np.ndarray, bound: float,
           sample_period: float) -> tuple[str, ...]:
    hints = []
    positive, negative = lags > 0, lags < 0
    magnitude = np.abs(r)
    if (outside & negative).any() and magnitude[negative].max() > 0.5 * magnitude.max():
        hints.append("feedback: significant correlation at negative lags (residual drives input)")
    if (outside & positive).any():
        right = magnitude[positive]
        d = int(np.argmax(right)) + 1
        width = int(np.sum(right > 0.5 * right[d - 1]))
        if width <= 2:
            hints.append(f"delay: sharp peak at lag {d} ({d * sample_period:.4g} s)")
        else:
            hints.append(f"lag: one-sided band over {width} positive lags, largest at lag {d}")
    elif outside[lags == 0].any():
        hints.append("static: correlation at lag 0 only (gain or direct feed-through error)")
    return tuple(hints)


@dataclass(frozen=True)
class ErrorModel(Serialisable):
    """Model error model ``G_e = B_i / A`` per input with its confidence radius per frequency.

    ``radius`` is ``sqrt(chi2_2(1 - alpha) lambda_max(cov[Re G_e, Im G_e]))``: outside it (``|G_e| >
    radius``) ``G_e`` differs from zero at that frequency, i.e. the nominal model is falsified.
    Only frequencies where the input carries power (``excited``: within 40 dB of its peak) can be
    falsified: beyond the excited band the estimate is an extrapolation.
    """

    input_names: tuple[str, ...]
    order_b: int
    order_a: int
    frequencies: np.ndarray
    response: np.ndarray = field(repr=False)
    radius: np.ndarray = field(repr=False)
    falsified: np.ndarray = field(repr=False)
    relative_error: np.ndarray | None = field(default=None, repr=False)
    excited: np.ndarray | None = field(default=None, repr=False)

    def falsified_bands(self, index: int = 0) -> list[tuple[float, float]]:
        """Frequency intervals [Hz] where input `index`'s error model leaves its band."""
        mask = self.falsified[index]
        edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(int), 0]))
        return [(float(self.frequencies[a]), float(self.frequencies[b - 1]))
                for a, b in zip(edges[::2], edges[1::2])]

    def to_dict(self) -> dict:
        """Summary per input plus the magnitude, radius and falsified mask per frequency."""
        out = {"order_b": self.order_b, "order_a": self.order_a,
               "frequencies_hz": self.frequencies, "inputs": {}}
        for i, name in enumerate(self.input_names):
            entry = {"magnitude": np.abs(self.response[i]), "radius": self.radius[i],
                     "falsified": self.falsified[i], "falsified_bands_hz": self.falsified_bands(i),
                     "falsified_share": float(np.mean(self.falsified[i]))}
            if self.relative_error is not None:
                entry["relative_error"] = self.relative_error[i]
                entry["max_relative_error"] = float(np.max(self.relative_error[i]))
            out["inputs"][name] = entry
        return jsonable(out)  # type: ignore[return-value]


@dataclass(frozen=True)
class ErrorModelOptions:
    """Orders, frequency grid and confidence level of the model error model
    (:func:`fit_error_model`)."""

    order_b: int = 20
    """FIR length ``nb`` per input [samples]."""
    order_a: int = 4
    """Order of ``A(q)`` (0: the FIR form)."""
    n_frequencies: int = 256
    """Points of the frequency grid from 0 to the Nyquist frequency."""
    alpha: float = 0.01
    """Level of the confidence radius of the response (1 - alpha coverage)."""


def fit_error_model(u: np.ndarray, residual: np.ndarray, sample_period: float, *,
                    input_names: Sequence[str] | None = None,
                    nominal_response: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None,
                    options: ErrorModelOptions = ErrorModelOptions()) -> ErrorModel:
    """Fit the model error model ``A(q) eps(t) = sum_i sum_{k<nb} b_ik u_i(t-k) + e(t)``.

    ``order_a = 0`` gives the FIR form; ``order_a > 0`` whitens a coloured free-run residual so that
    the covariance ``sigma^2 (Phi^T Phi)^-1`` is honest. The response and its Jacobian are
    ``G_i = B_i / A``, ``dG_i/db_ik = e^{-jwk} / A``, ``dG_i/da_k = -G_i e^{-jwk} / A``.
    `nominal_response` (``(n_u, n_frequencies)`` complex at :attr:`ErrorModel.frequencies`, or a
    callable of the frequencies [Hz]) gives ``|G_e / G|``. `sample_period` in [s]; `options`
    gives ``nb``, ``na``, the frequency grid and the confidence level.
    """
    order_b, order_a = options.order_b, options.order_a
    n_frequencies, alpha = options.n_frequencies, options.alpha
    eps = finite_column(residual, "residual")
    u = _matrix(u, len(eps), "inputs")
    names = tuple(input_names or (f"u{i}" for i in range(u.shape[1])))
    start = max(order_b - 1, order_a)
    rows = slice(start, len(eps))
    columns = [u[start - k:len(eps) - k, i] for i in range(u.shape[1]) for k in range(order_b)]
    columns += [-eps[start - k:len(eps) - k] for k in range(1, order_a + 1)]
    phi = np.column_stack(columns)
    theta, *_ = np.linalg.lstsq(phi, eps[rows], rcond=None)
    dof = max(len(phi) - phi.shape[1], 1)
    sigma2 = float(np.sum((eps[rows] - phi @ theta) ** 2) / dof)
    factor = _covariance_factor(phi, sigma2)
    frequencies = np.linspace(0.0, 0.5 / sample_period, n_frequencies)
    shift = np.exp(-2j * np.pi * frequencies * sample_period)
    a_poly = 1 + sum(theta[u.shape[1] * order_b + k - 1] * shift ** k for k in range(1, order_a + 1))
    powers_b = np.stack([shift ** k for k in range(order_b)])
    powers_a = np.stack([shift ** k for k in range(1, order_a + 1)]) if order_a else np.zeros((0, len(shift)))
    level = math.sqrt(stats.chi2.ppf(1 - alpha, 2))
    response, radius = [], []
    for i in range(u.shape[1]):
        g = theta[i * order_b:(i + 1) * order_b] @ powers_b / a_poly
        jac = np.zeros((phi.shape[1], len(shift)), complex)
        jac[i * order_b:(i + 1) * order_b] = powers_b / a_poly
        jac[u.shape[1] * order_b:] = -g * powers_a / a_poly
        radius.append(level * np.sqrt(_largest_variance(jac, factor)))
        response.append(g)
    response, radius = np.array(response), np.array(radius)
    relative = None
    if nominal_response is not None:
        nominal = nominal_response(frequencies) if callable(nominal_response) else nominal_response
        nominal = np.asarray(nominal, complex).reshape(response.shape)
        relative = np.abs(response) / np.maximum(np.abs(nominal), 1e-300)
    excited = np.array([excited_band(u[:, i], sample_period, frequencies)
                        for i in range(u.shape[1])])
    return ErrorModel(names, order_b, order_a, frequencies, response, radius,
                      (np.abs(response) > radius) & excited, relative, excited)


def excited_band(u: np.ndarray, sample_period: float, frequencies: np.ndarray, *,
                 dynamic_range_db: float = 40.0) -> np.ndarray:
    """Frequencies where `u` carries power within `dynamic_range_db` of its peak (Welch)."""
    x = np.asarray(u, float) - np.mean(u)
    f, power = sps.welch(x, 1.0 / sample_period, nperseg=min(len(x), 256))
    if not np.any(power > 0):
        return np.zeros(len(frequencies), bool)
    level = np.interp(frequencies, f, power)
    return level > np.max(power) * 10 ** (-dynamic_range_db / 10)


def _covariance_factor(phi: np.ndarray, sigma2: float) -> np.ndarray:
    """``F`` with ``F F^T = sigma2 (Phi^T Phi)^+`` (the pseudo-inverse's cut-off: singular values
    of ``Phi^T Phi`` below 1e-15 of the largest dropped), from the SVD of ``Phi``. Quadratic forms
    through ``F`` are sums of squares, never negative: those through the explicit inverse of an
    ill-conditioned ``Phi^T Phi`` (steps on an input, 8 nearly equal lagged columns) came out
    negative by rounding (seen two-mass/extra_mode/2497: a NaN band on the pressure)."""
    _, s, vt = np.linalg.svd(phi, full_matrices=False)
    keep = s ** 2 > 1e-15 * s[0] ** 2 if s.size and s[0] > 0 else np.zeros(s.size, bool)
    return math.sqrt(sigma2) * vt[keep].T / s[keep]


def _largest_variance(jac: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of the 2x2 covariance of (Re G, Im G) per frequency, the parameters'
    covariance ``factor factor^T`` (:func:`_covariance_factor`): a Gram matrix, so never negative."""
    fr, fi = factor.T @ jac.real, factor.T @ jac.imag
    vrr, vii, vri = np.sum(fr * fr, axis=0), np.sum(fi * fi, axis=0), np.sum(fr * fi, axis=0)
    half_trace = 0.5 * (vrr + vii)
    return half_trace + np.sqrt(np.maximum(0.25 * (vrr - vii) ** 2 + vri ** 2, 0.0))


@dataclass(frozen=True)
class NonlinearityTest(Serialisable):
    """Billings-Voon correlations of the residual with power signals; the verdict."""

    signals: tuple[str, ...]
    max_correlation: np.ndarray
    bounds: np.ndarray
    significant: np.ndarray
    kind: str
    """``"none"``, ``"odd"``, ``"even"`` or ``"even+odd"``."""


def check_nonlinearity(residual: np.ndarray, u: np.ndarray, y_hat: np.ndarray, *,
                       max_lag: int = 20, z: float = Z_99,
                       input_names: Sequence[str] | None = None) -> NonlinearityTest:
    """Correlate ``eps`` with ``u_i^2``, ``y_hat^2`` and ``y_hat^3`` over ``tau = -M..M``.

    Each power signal is first made orthogonal to ``[1, x]`` (x its base signal) so a linear misfit
    does not show as a nonlinearity. A kind is named when its correlation is significant and at
    least half as strong (in units of its bound) as the strongest one: the sample correlations of
    non-Gaussian power signals have heavier tails than the Bartlett bound assumes, so a cubic
    residual also nudges the squares over their bounds, far less than the cube.
    """
    eps = finite_column(residual, "residual")
    u = _matrix(u, len(eps), "inputs")
    y_hat = finite_column(y_hat, "y_hat")
    names = list(input_names or (f"u{i}" for i in range(u.shape[1])))
    candidates = [(f"{n}^2", u[:, i], 2) for i, n in enumerate(names)]
    candidates += [("y_hat^2", y_hat, 2), ("y_hat^3", y_hat, 3)]
    peaks, bounds = [], []
    for _, base, power in candidates:
        basis = np.column_stack([np.ones_like(base), base])
        target = base ** power
        coefficients, *_ = np.linalg.lstsq(basis, target, rcond=None)
        signal_ = target - basis @ coefficients
        _, r = cross_correlation(eps, signal_, max_lag)
        peaks.append(np.max(np.abs(r)))
        bounds.append(correlation_bound(eps, signal_, max_lag, z))
    peaks, bounds = np.array(peaks), np.array(bounds)
    significant = peaks > bounds
    strength = peaks / bounds
    top = float(strength.max())
    even = bool(significant[:-1].any()) and float(strength[:-1].max()) >= 0.5 * top
    odd = bool(significant[-1]) and float(strength[-1]) >= 0.5 * top
    kind = {(True, True): "even+odd", (True, False): "even", (False, True): "odd"}.get(
        (even, odd), "none")
    return NonlinearityTest(tuple(c[0] for c in candidates), peaks, bounds, significant, kind)


@dataclass(frozen=True)
class DetectionLines(Serialisable):
    """Power at excited, unexcited odd and unexcited even DFT lines of a periodic record."""

    n_periods: int
    excited_power: float
    odd_power: float
    even_power: float
    noise_power: float
    odd_over_even_db: float
    odd_detected: bool
    even_detected: bool


def excited_lines(u: np.ndarray, period: int, *, threshold_db: float = -40.0) -> np.ndarray:
    """DFT line indices (per period) where the input's power is within `threshold_db` of its peak."""
    x = finite_column(u, "input")
    n = (len(x) // period) * period
    spectrum = np.abs(np.fft.rfft(x[:n].reshape(-1, period).mean(axis=0))) ** 2
    spectrum[0] = 0.0
    return np.flatnonzero(spectrum > spectrum.max() * 10 ** (threshold_db / 10))


def detect_nonlinear_lines(x: np.ndarray, period: int, excited: Sequence[int], *,
                           max_line: int | None = None, alpha: float = 0.01) -> DetectionLines:
    """Odd/even nonlinear distortion from the unexcited lines of a periodic signal ``x``.

    ``x`` (output or residual) is cut into whole periods of `period` samples; the spectrum is
    averaged over periods and the noise power of that mean per line is ``var_P(X_k) / P``, pooled
    over the lines. A class of K lines is detected when its mean power exceeds that noise level
    by the ``chi2(2K)/(2K)`` quantile (needs two or more periods; with one, only the odd/even ratio is given).
    Lines run up to `max_line` (default: the highest excited line, the in-band region).
    """
    x = finite_column(x, "signal")
    n_periods = len(x) // period
    if n_periods < 1:
        raise IdentificationError(f"record of {len(x)} samples is shorter than one period {period}")
    spectra = np.fft.rfft(x[:n_periods * period].reshape(n_periods, period), axis=1) / period
    mean = spectra.mean(axis=0)
    excited = np.asarray(excited, int)
    top = int(max_line or excited.max())
    lines = np.arange(1, min(top, len(mean) - 1) + 1)
    free = lines[~np.isin(lines, excited)]
    odd, even = free[free % 2 == 1], free[free % 2 == 0]
    power = np.abs(mean) ** 2
    noise = (np.var(spectra, axis=0, ddof=1) / n_periods) if n_periods > 1 else np.full(len(mean), np.nan)
    noise_level = float(np.mean(noise[lines])) if n_periods > 1 else math.nan

    def detected(group: np.ndarray) -> bool:
        if n_periods < 2 or len(group) == 0:
            return False
        threshold = stats.chi2.ppf(1 - alpha, 2 * len(group)) / (2 * len(group))
        return float(np.mean(power[group])) > threshold * noise_level

    p_odd = float(np.mean(power[odd])) if len(odd) else math.nan
    p_even = float(np.mean(power[even])) if len(even) else math.nan
    return DetectionLines(n_periods, float(np.mean(power[excited])), p_odd, p_even, noise_level,
                          10 * math.log10(p_odd / p_even) if p_even > 0 else math.nan,
                          detected(odd), detected(even))


@dataclass(frozen=True)
class OutputAnalysis(Serialisable):
    """Every residual test for one output."""

    output_name: str
    fit: float
    residual_rms: float
    residual_mean: float
    energy_ratio: float
    whiteness: WhitenessTest
    cross_correlation: tuple[CrossCorrelationTest, ...]
    error_model: ErrorModel
    bands: BandEnergy
    segments: SegmentEnergy
    nonlinearity: NonlinearityTest
    conditions: tuple[ConditionEnergy, ...] = ()

    def to_dict(self) -> dict:
        """JSON-ready summary (spectra left out; the error model per input)."""
        out = {name: getattr(self, name) for name in
               ("output_name", "fit", "residual_rms", "residual_mean", "energy_ratio")}
        out["whiteness"] = self.whiteness.to_dict()
        out["cross_correlation"] = [c.to_dict() for c in self.cross_correlation]
        out["error_model"] = self.error_model.to_dict()
        bands = self.bands.to_dict()
        for key in ("frequencies", "residual_psd", "measured_psd"):
            bands.pop(key)
        out["bands"] = bands
        out["segments"] = self.segments.to_dict()
        out["nonlinearity"] = self.nonlinearity.to_dict()
        out["conditions"] = [c.to_dict() for c in self.conditions]
        return jsonable(out)  # type: ignore[return-value]


def analyse_residuals(data: IdentificationData, y_hat: np.ndarray, *,
                      conditions: Mapping[str, np.ndarray] | None = None,
                      velocity: np.ndarray | None = None, max_lag: int = 25,
                      error_model: ErrorModelOptions = ErrorModelOptions()
                      ) -> list[OutputAnalysis]:
    """Run every test of this module on each output's free-run residual ``y - y_hat``.

    `data` holds the inputs ``u``, the measured outputs ``y`` and their names; `y_hat` (N,
    n_outputs) is the model's free run on it. `conditions` maps a variable name (height,
    pressure, amplitude...) to its samples for :func:`energy_by_condition`; `velocity` adds
    :func:`energy_by_velocity`; `max_lag` [samples] bounds the correlation tests; `error_model`
    sets :func:`fit_error_model`. Missing (NaN) measured samples count as zero residual.
    """
    y = np.asarray(data.outputs, float).reshape(len(data), -1)
    y_hat = np.asarray(y_hat, float).reshape(y.shape)
    u = _matrix(data.inputs, len(y), "inputs")
    sample_period = data.sample_period
    inputs, outputs = list(data.input_names), list(data.output_names)
    results = []
    for j, name in enumerate(outputs):
        measured = np.where(np.isfinite(y[:, j]), y[:, j], y_hat[:, j])
        eps = measured - y_hat[:, j]
        crosses = tuple(check_cross_correlation(eps, u[:, i], max_lag, input_name=n,
                                                sample_period=sample_period)
                        for i, n in enumerate(inputs))
        found = [energy_by_condition(eps, v, name=k) for k, v in (conditions or {}).items()]
        if velocity is not None:
            found.append(energy_by_velocity(eps, velocity))
        spread = float(np.sum((measured - measured.mean()) ** 2))
        results.append(OutputAnalysis(
            name, float(fit_percent(measured, y_hat[:, j])), float(np.sqrt(np.mean(eps ** 2))),
            float(eps.mean()), float(np.sum(eps ** 2) / spread) if spread > 0 else math.nan,
            check_whiteness(eps, max_lag), crosses,
            fit_error_model(u, eps, sample_period, input_names=inputs, options=error_model),
            energy_by_band(measured, eps, sample_period),
            energy_by_segment(measured, eps, sample_period),
            check_nonlinearity(eps, u, y_hat[:, j], input_names=inputs), tuple(found)))
    return results
