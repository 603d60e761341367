"""Where in frequency, time and operating condition a residual's energy lies (the diagnosis' first
and third questions: where the gap lies, how far it shrinks): the energy functions of the residual
analysis (:mod:`panto.identification.diagnosis.residual_analysis`) and the JSON helpers its results
share.

- per frequency band: Welch spectra of residual and measurement, power per band (octaves down from
  the Nyquist frequency by default), ``ratio = P_eps / P_y`` and the residual's share;
- per time segment: sliding-window RMS, fit and share;
- per operating condition: residual RMS, mean and concentration (energy share over time share)
  per bin of a variable (velocity sign and magnitude, amplitude, height, pressure).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import signal as sps

from panto.identification.estimation.base import IdentificationError, fit_percent

def finite_column(x: np.ndarray, name: str) -> np.ndarray:
    """`x` as a flat float array; raises IdentificationError naming `name` at a NaN or inf."""
    x = np.asarray(x, float).ravel()
    if not np.all(np.isfinite(x)):
        raise IdentificationError(f"{name}: holds NaN or inf at sample {int(np.argmin(np.isfinite(x)))}")
    return x


def jsonable(value: object) -> object:
    """Plain JSON types from dicts, sequences and numpy values; NaN and inf as None."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return None if not math.isfinite(float(value)) else float(value)
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


class Serialisable:
    """Mixin for dataclasses: :meth:`to_dict` gives their fields as plain JSON types."""

    def to_dict(self) -> dict:
        """JSON-ready dictionary (arrays as lists, NaN as None)."""
        return jsonable(asdict(self))  # type: ignore[arg-type]


@dataclass(frozen=True)
class BandEnergy(Serialisable):
    """Residual against measured power per frequency band (Welch PSDs)."""

    frequencies: np.ndarray = field(repr=False)
    residual_psd: np.ndarray = field(repr=False)
    measured_psd: np.ndarray = field(repr=False)
    band_edges: np.ndarray
    residual_power: np.ndarray
    measured_power: np.ndarray
    ratio: np.ndarray
    share: np.ndarray


def energy_by_band(measured: np.ndarray, residual: np.ndarray, sample_period: float, *,
                   band_edges: Sequence[float] | None = None,
                   segment_length: int | None = None) -> BandEnergy:
    """Welch spectra of residual and measurement; per band the power ratio and residual share.

    Default bands: octaves down from the Nyquist frequency to the Welch resolution.
    ``ratio = P_eps / P_y`` (1 = the model explains nothing there); ``share`` = part of the total
    residual power lying in the band.
    """
    eps, y = finite_column(residual, "residual"), finite_column(measured, "measured")
    fs = 1.0 / sample_period
    nperseg = segment_length or min(len(eps), 1024)
    f, p_eps = sps.welch(eps, fs, nperseg=nperseg)
    _, p_y = sps.welch(y, fs, nperseg=nperseg)
    if band_edges is None:
        top, low = fs / 2, f[1] if len(f) > 1 else fs / 2
        octaves = int(max(1, min(8, math.floor(math.log2(top / low)))))
        band_edges = [0.0] + [top / 2 ** k for k in range(octaves, -1, -1)]
    edges = np.asarray(band_edges, float)
    df = f[1] - f[0] if len(f) > 1 else fs / 2
    index = np.clip(np.searchsorted(edges, f, side="right") - 1, 0, len(edges) - 2)
    p_band_eps = np.bincount(index, p_eps * df, len(edges) - 1)
    p_band_y = np.bincount(index, p_y * df, len(edges) - 1)
    ratio = p_band_eps / np.where(p_band_y > 0, p_band_y, np.nan)
    share = p_band_eps / max(p_band_eps.sum(), 1e-300)
    return BandEnergy(f, p_eps, p_y, edges, p_band_eps, p_band_y, ratio, share)


@dataclass(frozen=True)
class SegmentEnergy(Serialisable):
    """Residual RMS and fit per sliding time window."""

    start_times: np.ndarray
    window: float
    residual_rms: np.ndarray
    fit: np.ndarray
    share: np.ndarray


def energy_by_segment(measured: np.ndarray, residual: np.ndarray, sample_period: float, *,
                      window: float | None = None, step: float | None = None,
                      start_time: float = 0.0) -> SegmentEnergy:
    """Sliding-window residual RMS, fit [%] and share of residual energy (windows may overlap).

    Default window: a twentieth of the record; default step: half a window.
    """
    eps, y = finite_column(residual, "residual"), finite_column(measured, "measured")
    n = len(eps)
    length = max(2, round(window / sample_period) if window else n // 20)
    hop = max(1, round(step / sample_period) if step else length // 2)
    starts = np.arange(0, max(n - length, 0) + 1, hop)
    rms = np.array([np.sqrt(np.mean(eps[s:s + length] ** 2)) for s in starts])
    fits = np.array([fit_percent(y[s:s + length], y[s:s + length] - eps[s:s + length])
                     for s in starts])
    energy = rms ** 2
    return SegmentEnergy(start_time + starts * sample_period, length * sample_period, rms,
                         fits, energy / max(energy.sum(), 1e-300))


@dataclass(frozen=True)
class ConditionEnergy(Serialisable):
    """Residual per bin of an operating variable (velocity, amplitude, height, pressure...).

    ``concentration`` = share of residual energy / share of time: above 1 where the gap gathers.
    """

    variable: str
    edges: np.ndarray
    count: np.ndarray
    residual_rms: np.ndarray
    residual_mean: np.ndarray
    share: np.ndarray
    concentration: np.ndarray


def energy_by_condition(residual: np.ndarray, variable: np.ndarray, *, name: str = "variable",
                        edges: Sequence[float] | None = None, n_bins: int = 5) -> ConditionEnergy:
    """Residual statistics per bin of `variable` (default: `n_bins` equally populated bins)."""
    eps, x = finite_column(residual, "residual"), finite_column(variable, name)
    if len(x) != len(eps):
        raise IdentificationError(f"{name}: {len(x)} samples for a residual of {len(eps)}")
    if edges is None:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
    edges = np.asarray(edges, float)
    if len(edges) < 2:  # a constant variable (an input held fixed): one bin holds everything
        edges = np.array([float(np.min(x)), float(np.max(x))])
    index = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    count = np.bincount(index, minlength=len(edges) - 1)
    energy = np.bincount(index, eps ** 2, len(edges) - 1)
    total = np.bincount(index, eps, len(edges) - 1)
    safe = np.maximum(count, 1)
    share = energy / max(energy.sum(), 1e-300)
    concentration = share / np.maximum(count / len(eps), 1e-300)
    return ConditionEnergy(name, edges, count, np.sqrt(energy / safe), total / safe, share,
                           np.where(count > 0, concentration, np.nan))


def energy_by_velocity(residual: np.ndarray, velocity: np.ndarray, *, n_magnitude_bins: int = 3,
                       name: str = "velocity") -> ConditionEnergy:
    """Bins of velocity sign and magnitude: ``-inf, -q_k, ..., 0, ..., q_k, inf`` (|v| quantiles).

    Coulomb friction and backlash gather the residual near zero velocity and flip its mean with
    the sign.
    """
    v = finite_column(velocity, name)
    q = np.quantile(np.abs(v), np.linspace(0, 1, n_magnitude_bins + 1)[1:-1])
    edges = np.r_[-np.inf, -q[::-1], 0.0, q, np.inf]
    return energy_by_condition(residual, v, name=name, edges=np.unique(edges))


def moving_amplitude(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving RMS of the mean-removed signal: an amplitude variable for conditions."""
    x = finite_column(x, "signal")
    kernel = np.ones(max(1, window)) / max(1, window)
    return np.sqrt(np.convolve((x - x.mean()) ** 2, kernel, mode="same"))
