"""Preprocessing of rig runs before identification (thesis section 4.2).

The thesis recorded at 500 Hz, resampled to the camera's 50 Hz and low-pass filtered every signal
with a stop band at 20 Hz (the camera's Nyquist frequency is 25 Hz). Here the order is the one that
avoids aliasing: a zero-phase low-pass at the recording rate (it is also the anti-aliasing filter),
then every ``ratio``-th sample is kept.

Filter design (:func:`design_lowpass`)
    A Butterworth low-pass (maximally flat, monotone: no ripple on the identification signals) of
    the lowest order ``n`` that meets, *after the forward-backward pass* (magnitude squared,
    ``|H_zp(f)| = |H(f)|^2``)::

        attenuation(f_pass) <= 0.1 dB,   attenuation(f_stop) >= 40 dB,

    i.e. the single pass is designed for half of each figure in dB (:func:`scipy.signal.buttord`).
    Defaults: ``f_stop = 20 Hz``, ``f_pass = f_stop / 2 = 10 Hz`` (thesis section 4.3: the video
    positions are reliable up to 10 Hz). At 500 Hz this gives a 7th-order filter. Zero phase:
    :func:`scipy.signal.sosfiltfilt` (odd extension at the ends), so filtered signals are not
    delayed relative to each other or to the camera positions.

Also :func:`check_aliasing`: two runs recorded at mutually prime rates (e.g. 500 and 487 Hz) see
a component above the lower Nyquist frequency at *different* alias frequencies; where their
spectra disagree, aliasing is suspected (thesis Fig. 4.1);
:func:`panto.identification.data.plots.plot_aliasing_check` draws the two spectrograms and spectra
as that figure.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from panto.rig.dataset import Dataset

#: Channels holding states or bits: picked, never filtered (a filtered bit is meaningless).
DISCRETE_CHANNELS = frozenset({"led", "drive_state", "drive_error", "dynamic_gain_switch"})


class PreprocessingError(ValueError):
    """A dataset or an option cannot be preprocessed; the message names channel and value."""


@dataclass(frozen=True)
class LowpassDesign:
    """A zero-phase Butterworth low-pass: second-order sections and what they guarantee.

    Attributes
    ----------
    sos : ndarray, shape (k, 6)
        Single-pass filter; applied forward and backward.
    order : int
    sample_rate, passband, stopband, cutoff : float
        [Hz]; `cutoff` is the single pass' -3 dB frequency.
    passband_loss, stopband_attenuation : float
        Guaranteed zero-phase figures [dB] (loss <= at `passband`, attenuation >= at `stopband`).
    support : int
        Half-width [samples] of the zero-phase impulse response holding 99.9 % of its absolute
        sum: an output sample depends (to that level) on inputs within +-support samples.
    """

    sos: np.ndarray
    order: int
    sample_rate: float
    passband: float
    stopband: float
    cutoff: float
    passband_loss: float
    stopband_attenuation: float
    support: int

    def describe(self) -> dict[str, float | int | str]:
        """JSON-ready summary (for metadata)."""
        return {"type": "butterworth, forward-backward (zero phase)", "order": self.order,
                "sample_rate_hz": self.sample_rate, "passband_hz": self.passband,
                "stopband_hz": self.stopband, "cutoff_hz": self.cutoff,
                "passband_loss_db": self.passband_loss,
                "stopband_attenuation_db": self.stopband_attenuation,
                "support_samples": self.support}


def design_lowpass(sample_rate: float, *, stopband: float = 20.0, passband: float | None = None,
                   attenuation: float = 40.0, passband_loss: float = 0.1) -> LowpassDesign:
    """Design the zero-phase low-pass described in the module notes.

    Parameters
    ----------
    sample_rate : float
        [Hz].
    stopband : float
        Stop-band edge [Hz] (thesis: 20 Hz); below the Nyquist frequency.
    passband : float, optional
        Pass-band edge [Hz]; default ``stopband / 2``.
    attenuation, passband_loss : float
        Zero-phase attenuation at `stopband` (>=) and loss at `passband` (<=) [dB].
    """
    from scipy import signal

    passband = 0.5 * stopband if passband is None else float(passband)
    nyquist = 0.5 * sample_rate
    if not (0.0 < passband < stopband < nyquist):
        raise PreprocessingError(f"low-pass edges: need 0 < passband ({passband} Hz) < stopband "
                                 f"({stopband} Hz) < Nyquist ({nyquist} Hz)")
    order, cutoff = signal.buttord(passband, stopband, passband_loss / 2, attenuation / 2,
                                   fs=sample_rate)
    sos = signal.butter(order, cutoff, btype="low", output="sos", fs=sample_rate)
    return LowpassDesign(sos=sos, order=int(order), sample_rate=float(sample_rate),
                         passband=passband, stopband=float(stopband), cutoff=float(cutoff),
                         passband_loss=passband_loss, stopband_attenuation=attenuation,
                         support=_impulse_support(sos))


def _impulse_support(sos: np.ndarray, fraction: float = 0.999) -> int:
    """Half-width of the zero-phase impulse response holding `fraction` of its absolute sum."""
    from scipy import signal

    length = 1
    while True:
        length *= 2
        impulse = np.zeros(2 * length + 1)
        impulse[length] = 1.0
        response = np.abs(signal.sosfiltfilt(sos, impulse, padlen=0))
        total = response.sum()
        cumulative = np.array([response[length - w: length + w + 1].sum()
                               for w in range(length + 1)])
        width = int(np.argmax(cumulative >= fraction * total))
        if cumulative[width] >= fraction * total and width < length // 2:
            return width


def lowpass_zero_phase(x: np.ndarray, sample_rate: float, *, stopband: float = 20.0,
                       passband: float | None = None, axis: int = 0) -> np.ndarray:
    """Zero-phase low-pass of `x` along `axis` (design in the module notes).

    Parameters
    ----------
    x : array_like
        Finite samples at `sample_rate`.
    sample_rate : float
        [Hz].
    stopband, passband : float
        Edges [Hz], see :func:`design_lowpass`.
    axis : int

    Returns
    -------
    ndarray
        Same shape; ``|X_out(f)| = |H(f)|^2 |X(f)|`` with no phase shift.
    """
    from scipy import signal

    x = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(x)):
        raise PreprocessingError("lowpass_zero_phase: the signal holds NaN or inf; use "
                                 "resample_dataset for channels with gaps")
    design = design_lowpass(sample_rate, stopband=stopband, passband=passband)
    n = x.shape[axis]
    if n < 2:
        return x.copy()
    padlen = min(3 * (2 * len(design.sos) + 1), n - 1)
    return signal.sosfiltfilt(design.sos, x, axis=axis, padlen=padlen)


def butterworth_zero_phase(x: np.ndarray, cutoff: float, sample_rate: float, *, order: int = 4,
                           axis: int = 0) -> np.ndarray:
    """`x` through a Butterworth low-pass of `order` at `cutoff` [Hz], forward and backward.

    A fixed filter given by its cut-off, as benchmarks prescribe their prefilters (EMPS: Janot et
    al. 2019, 4th order at 25 Hz), where :func:`lowpass_zero_phase` designs the order from band
    edges. Raises :class:`ValueError` when `cutoff` is not below the Nyquist frequency.
    """
    from scipy import signal

    nyquist = 0.5 * sample_rate
    if not 0.0 < cutoff < nyquist:
        raise ValueError(f"lowpass {cutoff:g} Hz: must be below the Nyquist frequency "
                         f"{nyquist:g} Hz of the record")
    sos = signal.butter(order, cutoff / nyquist, output="sos")
    return signal.sosfiltfilt(sos, np.asarray(x, float), axis=axis)


def decimate_zero_phase(x: np.ndarray, factor: int, *, axis: int = 0) -> np.ndarray:
    """Every `factor`-th sample of `x` (from the first) after a zero-phase anti-aliasing filter.

    The filter is a fixed 8th-order Butterworth low-pass at ``0.8 / factor`` of the Nyquist
    frequency (0.8 of the new one), run forward and backward (:func:`scipy.signal.sosfiltfilt`,
    default padding). Unlike :func:`resample_dataset` it needs no rate or band edges: it is the
    decimation of plain tables (``panto diagnose --rate``). ``factor <= 1`` returns `x` as is.
    """
    from scipy import signal

    if factor <= 1:
        return x
    sos = signal.butter(8, 0.8 / factor, output="sos")
    filtered = signal.sosfiltfilt(sos, x, axis=axis)
    return np.take(filtered, np.arange(0, filtered.shape[axis], factor), axis=axis)


def _filter_with_gaps(values: np.ndarray, design: LowpassDesign) -> tuple[np.ndarray, np.ndarray]:
    """Filter a channel that may hold NaN: gaps bridged linearly (ends held) for the filter;
    returns the filtered values and the mask of samples whose support touched a gap."""
    from scipy import signal

    missing = np.isnan(values)
    if missing.all():
        return values.copy(), missing.copy()
    filled = values.copy()
    if missing.any():
        index = np.arange(values.size)
        filled[missing] = np.interp(index[missing], index[~missing], values[~missing])
    padlen = min(3 * (2 * len(design.sos) + 1), values.size - 1)
    filtered = signal.sosfiltfilt(design.sos, filled, padlen=padlen) if values.size > 1 \
        else filled
    touched = missing.copy()
    if missing.any():
        touched = _dilate(missing, design.support)
    return filtered, touched


def _dilate(mask: np.ndarray, width: int) -> np.ndarray:
    """``out[i]`` is true when any ``mask[j]`` with ``|i - j| <= width`` is."""
    counts = np.concatenate([[0], np.cumsum(mask.astype(np.int64))])
    index = np.arange(mask.size)
    upper = np.minimum(index + width + 1, mask.size)
    lower = np.maximum(index - width, 0)
    return counts[upper] - counts[lower] > 0


def resample_dataset(dataset: Dataset, rate: float = 50.0, *, stopband: float = 20.0,
                     passband: float | None = None,
                     channels: Sequence[str] | None = None) -> Dataset:
    """Low-pass (zero phase) and decimate a run to `rate` (thesis section 4.2: 500 -> 50 Hz).

    Parameters
    ----------
    dataset : Dataset
        Uniformly sampled at ``dataset.metadata.sample_rate``.
    rate : float
        Target rate [Hz]; ``sample_rate / rate`` must be a whole number (1 only filters).
    stopband, passband : float
        Filter edges [Hz] (:func:`design_lowpass`); `stopband` below ``rate / 2``.
    channels : sequence of str, optional
        Channels to keep (default all).

    Returns
    -------
    Dataset
        Every ``ratio``-th sample from the first, filtered; channels in
        :data:`DISCRETE_CHANNELS` or ending in ``_valid`` are picked unfiltered. A channel with
        NaN gaps is bridged linearly for the filter and NaN is put back on every output sample
        whose filter support (``+-design.support`` input samples) touched a gap. The metadata
        gets the new rate and ``extra["preprocessing"]`` (a list of steps) records the step.
    """
    source_rate = float(dataset.metadata.sample_rate)
    step = _resample_step(source_rate, rate, stopband)
    _check_uniform(dataset.time, source_rate)
    names = list(dataset.names) if channels is None else list(channels)
    unknown = [n for n in names if n not in dataset.channels]
    if unknown:
        raise PreprocessingError(f"resample: channel(s) {unknown} not in the dataset; channels "
                                 f"are {list(dataset.names)}")
    design = design_lowpass(source_rate, stopband=stopband, passband=passband)
    out, gap_samples = _decimated_channels(dataset, names, design, step)
    record = {"step": "resample", "from_rate_hz": source_rate, "to_rate_hz": float(rate),
              "keep": f"every {step}th sample from the first", "filter": design.describe(),
              "unfiltered_channels": [n for n in names if n in DISCRETE_CHANNELS
                                      or n.endswith("_valid")],
              "nan_samples_from_gaps": gap_samples}
    extra = dict(dataset.metadata.extra)
    extra["preprocessing"] = [*extra.get("preprocessing", []), record]
    metadata = replace(dataset.metadata, sample_rate=float(rate), extra=extra)
    return Dataset(dataset.time[::step], out, {n: dataset.units[n] for n in names}, metadata,
                   dataset.warnings)


def _resample_step(source_rate: float, rate: float, stopband: float) -> int:
    """The decimation factor ``source_rate / rate`` [samples]; checks it is whole and that
    `stopband` [Hz] lies below the target Nyquist frequency."""
    ratio = source_rate / rate
    step = int(round(ratio))
    if step < 1 or abs(ratio - step) > 1e-9 * ratio:
        raise PreprocessingError(f"resample: {source_rate} Hz -> {rate} Hz is a ratio of "
                                 f"{ratio:.6g}, not a whole number; pick a rate that divides "
                                 f"{source_rate} Hz")
    if stopband >= 0.5 * rate:
        raise PreprocessingError(f"resample: stopband {stopband} Hz must lie below the target "
                                 f"Nyquist frequency {0.5 * rate} Hz (else it aliases)")
    return step


def _decimated_channels(dataset: Dataset, names: Sequence[str], design: LowpassDesign,
                        step: int) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Every `step`-th sample of each channel, low-passed unless discrete; per channel with gaps
    the NaN output samples whose filter support touched a gap."""
    out: dict[str, np.ndarray] = {}
    gap_samples: dict[str, int] = {}
    for name in names:
        values = np.array(dataset[name], dtype=float)
        if name in DISCRETE_CHANNELS or name.endswith("_valid"):
            out[name] = values[::step]
            continue
        filtered, touched = _filter_with_gaps(values, design)
        filtered[touched] = np.nan
        out[name] = filtered[::step]
        if touched.any():
            gap_samples[name] = int(np.isnan(out[name]).sum())
    return out, gap_samples


def _check_uniform(time: np.ndarray, sample_rate: float) -> None:
    if time.size < 2:
        return
    steps = np.diff(time)
    bad = np.flatnonzero(np.abs(steps * sample_rate - 1.0) > 1e-6)
    if bad.size:
        row = int(bad[0])
        raise PreprocessingError(f"resample: time is not uniform at {sample_rate} Hz: step "
                                 f"{steps[row]!r} s at row {row + 1} (t = {time[row]!r} s)")


# --- aliasing check (thesis section 4.2, Fig. 4.1) ---------------------------------------------


@dataclass(frozen=True)
class AliasingCheck:
    """Comparison of one channel's spectra from two runs at mutually prime rates.

    Attributes
    ----------
    channel : str
    rates : tuple of float
        The two sample rates [Hz].
    coprime : bool
        Whether the (whole-number) rates are mutually prime (else aliases may coincide).
    max_frequency : float
        Compared up to the lower Nyquist frequency [Hz].
    frequencies : tuple of ndarray
        Welch frequency grids [Hz] of the two runs (same resolution, up to `max_frequency`).
    spectra : tuple of ndarray
        One-sided power spectral densities [unit^2/Hz].
    band_edges : ndarray, shape (b + 1,)
        [Hz].
    band_levels : ndarray, shape (2, b)
        Band powers [dB re the strongest band of either run].
    band_difference : ndarray, shape (b,)
        ``level_first - level_second`` [dB]: the per-band agreement figure (0 dB: equal power).
    relevant : ndarray of bool, shape (b,)
        Bands above `floor_db` in at least one run (others are too weak to judge).
    tolerance_db, floor_db : float
    aliasing_suspected : bool
        Some relevant band differs by more than `tolerance_db`.
    where : tuple of (float, float, float)
        ``(f_low, f_high, difference_db)`` of each suspect band.
    spectrograms : tuple of (ndarray, ndarray, ndarray)
        ``(frequencies, times, power)`` of each run, for the plot.
    """

    channel: str
    rates: tuple[float, float]
    coprime: bool
    max_frequency: float
    frequencies: tuple[np.ndarray, np.ndarray]
    spectra: tuple[np.ndarray, np.ndarray]
    band_edges: np.ndarray
    band_levels: np.ndarray
    band_difference: np.ndarray
    relevant: np.ndarray
    tolerance_db: float
    floor_db: float
    aliasing_suspected: bool
    where: tuple[tuple[float, float, float], ...]
    spectrograms: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]

    def summary(self) -> dict:
        """JSON-ready verdict and per-band figures."""
        return {"channel": self.channel, "rates_hz": list(self.rates), "coprime": self.coprime,
                "max_frequency_hz": self.max_frequency,
                "aliasing_suspected": self.aliasing_suspected,
                "where": [{"f_low_hz": a, "f_high_hz": b, "difference_db": d}
                          for a, b, d in self.where],
                "tolerance_db": self.tolerance_db, "floor_db": self.floor_db,
                "bands": [{"f_low_hz": float(a), "f_high_hz": float(b),
                           "level_first_db": float(l1), "level_second_db": float(l2),
                           "difference_db": float(d), "relevant": bool(r)}
                          for a, b, l1, l2, d, r in zip(self.band_edges[:-1],
                                                        self.band_edges[1:],
                                                        *self.band_levels,
                                                        self.band_difference, self.relevant)]}


def _band_edges(max_frequency: float, band_width: float) -> np.ndarray:
    """Band edges [Hz] of `band_width` from 0 up to `max_frequency` (a last, narrower band)."""
    edges = np.arange(0.0, max_frequency + 1e-9, band_width)
    if edges[-1] < max_frequency - 1e-9:  # a last, narrower band up to the lower Nyquist
        edges = np.append(edges, max_frequency)
    if edges.size < 2:
        raise PreprocessingError(f"aliasing check: band_width {band_width} Hz exceeds the lower "
                                 f"Nyquist frequency {max_frequency} Hz")
    return edges


def _spectra(values: np.ndarray, rate: float, segment_duration: float,
             max_frequency: float) -> tuple[np.ndarray, np.ndarray, Any]:
    """Welch PSD [unit^2/Hz] up to `max_frequency` [Hz] and the spectrogram of one run."""
    from scipy import signal

    per_segment = min(values.size, int(round(segment_duration * rate)))
    f, psd = signal.welch(values, fs=rate, nperseg=per_segment, detrend="constant")
    keep = f <= max_frequency
    spectrogram = signal.spectrogram(values, fs=rate, nperseg=per_segment // 2,
                                     detrend="constant")
    return f[keep], psd[keep], spectrogram


def _channel_values(dataset: Dataset, channel: str, which: str) -> np.ndarray:
    if channel not in dataset.channels:
        raise PreprocessingError(f"aliasing check: {which} run has no channel {channel!r}; "
                                 f"channels are {list(dataset.names)}")
    values = np.array(dataset[channel], dtype=float)
    finite = np.isfinite(values)
    if finite.sum() < 16:
        raise PreprocessingError(f"aliasing check: {which} run, channel {channel!r}: only "
                                 f"{int(finite.sum())} finite samples")
    if not finite.all():  # bridge gaps linearly; they are short compared with a Welch segment
        index = np.arange(values.size)
        values[~finite] = np.interp(index[~finite], index[finite], values[finite])
    return values


def check_aliasing(first: Dataset, second: Dataset, channel: str = "force", *,
                   band_width: float = 5.0, segment_duration: float = 2.0,
                   tolerance_db: float = 6.0, floor_db: float = -50.0) -> AliasingCheck:
    """Compare a channel's spectra from two runs at mutually prime rates (thesis Fig. 4.1).

    A component at ``f`` above a run's Nyquist frequency ``fs / 2`` appears at the alias
    ``|f - k fs|`` (the nearest multiple ``k``); for two rates with ``gcd = 1`` the aliases land
    at different frequencies, so the two spectra disagree there. Both spectra are Welch estimates
    (Hann windows of `segment_duration`, half overlap, mean removed), integrated over bands of
    `band_width` up to the lower Nyquist frequency and compared in dB.

    Parameters
    ----------
    first, second : Dataset
        The two runs (same excitation), at different sample rates.
    channel : str
    band_width : float
        [Hz].
    segment_duration : float
        Welch segment length [s] (resolution ``1 / segment_duration``).
    tolerance_db : float
        Largest band difference still counted as agreement [dB].
    floor_db : float
        Bands weaker than this (re the strongest band) in both runs are not judged [dB].

    Returns
    -------
    AliasingCheck
    """
    rates = (float(first.metadata.sample_rate), float(second.metadata.sample_rate))
    if rates[0] == rates[1]:
        raise PreprocessingError(f"aliasing check: both runs are at {rates[0]} Hz; it needs two "
                                 "different (mutually prime) rates")
    max_frequency = 0.5 * min(rates)
    edges = _band_edges(max_frequency, band_width)
    frequencies, spectra, spectrograms = [], [], []
    for dataset, rate, which in zip((first, second), rates, ("first", "second")):
        values = _channel_values(dataset, channel, which)
        f, psd, spectrogram = _spectra(values, rate, segment_duration, max_frequency)
        frequencies.append(f)
        spectra.append(psd)
        spectrograms.append(spectrogram)
    powers = np.array([[np.trapezoid(p[(f >= a) & (f <= b)], f[(f >= a) & (f <= b)])
                        for a, b in zip(edges[:-1], edges[1:])]
                       for f, p in zip(frequencies, spectra)])
    reference = max(float(powers.max()), np.finfo(float).tiny)
    levels = 10.0 * np.log10(np.maximum(powers, reference * 1e-30) / reference)
    difference = levels[0] - levels[1]
    relevant = levels.max(axis=0) >= floor_db
    suspect = relevant & (np.abs(difference) > tolerance_db)
    where = tuple((float(edges[i]), float(edges[i + 1]), float(difference[i]))
                  for i in np.flatnonzero(suspect))
    coprime = all(float(r).is_integer() for r in rates) and \
        math.gcd(int(rates[0]), int(rates[1])) == 1
    return AliasingCheck(channel, rates, coprime, max_frequency, tuple(frequencies),
                         tuple(spectra), edges, levels, difference, relevant, tolerance_db,
                         floor_db, bool(suspect.any()), where, tuple(spectrograms))

