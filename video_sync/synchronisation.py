"""Aligning the camera's LED bits with the rig's 500 Hz LED output (thesis section 3.2).

The rig drives an LED with a pseudo-random binary sequence (holds of 6-30 ms, :mod:`panto.rig.sync_led`);
the 50 Hz camera, with a 2 ms shutter, sees one fine sample in ten. If camera frame ``k`` shows
fine sample ``shift + 10 k``, then for each start phase ``p = 0..9`` the camera sequence equals the
fine LED decimated from ``p`` (``d_p[j] = led[p + 10 j]``) delayed by the coarse ``lag``, and

    t_shift = lag * 10 + phase                                   (thesis eq. 3.1, 0-based)

Method
------
Bits are coded ``+1`` (on) / ``-1`` (off); an unknown camera bit (NaN) is coded 0 and counts
nowhere. The ten correlations ``r_p(lag) = sum_k c[k] d_p[lag + k]`` for every lag, negative ones
included (camera started before the recording), are computed at once as one FFT correlation of
the fine sequence with the camera sequence spread onto the fine grid (nine zeros between frames):
``r(shift) = sum_k c[k] led[shift + 10 k]``, so ``r_p(lag) = r(10 lag + p)``. The normalisation
is the camera's autocorrelation at zero lag over the overlapping frames (the number of known
camera bits that meet a fine sample), giving

    rho(shift) = r(shift) / N(shift) = 1 - 2 * (fraction of overlapping frames that disagree)

in [-1, 1]; its maximum (clipped to [0, 1]) is the *confidence* (0.8 with 10 % flipped bits).
Only shifts overlapping at least `min_overlap` frames compete.

The fine phase. Neighbouring shifts ``s`` and ``s + 1`` see different fine samples only in the
frames where an LED transition falls between them (with holds of 3-15 samples, about one frame in
nine), so their correlations differ by few counts (thesis Fig. 3.7: for short records the phase is
not determined). Maximising ``rho`` is the maximum-likelihood choice under independent bit errors:
it counts, frame by frame, agreement *at the transitions*, which is the finer criterion the thesis
asks for; no further rule is needed. When several adjacent shifts tie, the middle one is taken and
:attr:`SyncResult.tied_shifts` says how many tied (the uncertainty is then that many fine samples).

Uniqueness. The correlation stays high within about one hold time of the true shift, so the
competitor (`second_best`) is the best ``rho`` at least `exclusion` fine samples away (default two
camera frames). The alignment is refused (:class:`SyncError`) when the confidence is below
`min_confidence`, when ``peak_ratio = best / second_best`` is below `min_peak_ratio`, or when no
shift overlaps `min_overlap` frames.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class SyncError(ValueError):
    """The two LED sequences cannot be aligned with confidence; the message gives the numbers."""


@dataclass(frozen=True)
class SyncResult:
    """Alignment of camera frames with the fine (500 Hz) samples.

    Attributes
    ----------
    shift : int
        Camera frame ``k`` shows fine sample ``shift + decimation * k`` (may be negative).
    phase, lag : int
        ``shift = lag * decimation + phase``, ``0 <= phase < decimation`` (thesis eq. 3.1).
    confidence : float
        Normalised correlation at the best shift, in [0, 1] (1: every overlapping bit agrees).
    second_best : float
        Best normalised correlation at least `exclusion` fine samples from `shift`.
    peak_ratio : float
        ``confidence / second_best`` (inf when ``second_best <= 0``).
    overlap : int
        Camera frames with a known bit that meet a fine sample at `shift`.
    tied_shifts : int
        Shifts sharing the best correlation (1: the fine phase is determined).
    decimation : int
    shifts : ndarray
        Every candidate shift (for the plot).
    correlation : ndarray
        ``rho`` at each candidate shift (NaN where the overlap is below `min_overlap`).
    """

    shift: int
    phase: int
    lag: int
    confidence: float
    second_best: float
    peak_ratio: float
    overlap: int
    tied_shifts: int
    decimation: int
    shifts: np.ndarray
    correlation: np.ndarray

    def summary(self) -> dict[str, float | int]:
        """JSON-ready numbers (without the correlation arrays)."""
        return {"shift_samples": self.shift, "phase": self.phase, "lag": self.lag,
                "confidence": self.confidence, "second_best": self.second_best,
                "peak_ratio": self.peak_ratio if math.isfinite(self.peak_ratio) else None,
                "overlap_frames": self.overlap, "tied_shifts": self.tied_shifts,
                "decimation": self.decimation}

    def peaks_per_phase(self) -> np.ndarray:
        """Peak ``rho`` of each start phase's correlation (thesis Fig. 3.8b): for phase ``p`` the
        best value at the shifts ``s = p (mod decimation)`` within one frame of `shift`."""
        near = np.abs(self.shifts - self.shift) < self.decimation
        phases = np.mod(self.shifts[near], self.decimation)
        values = self.correlation[near]
        peaks = np.array([np.nanmax(values[phases == p], initial=-np.inf)
                          for p in range(self.decimation)])
        return np.where(np.isfinite(peaks), peaks, np.nan)


def _code(bits: np.ndarray, what: str, allow_unknown: bool) -> np.ndarray:
    bits = np.asarray(bits, dtype=float).ravel()
    known = np.isfinite(bits)
    if not allow_unknown and not known.all():
        raise SyncError(f"{what}: NaN at sample {int(np.flatnonzero(~known)[0])}; the fine LED "
                        "must be complete")
    bad = known & (bits != 0.0) & (bits != 1.0)
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise SyncError(f"{what}: value {bits[index]!r} at sample {index} is not a bit (0/1)")
    return np.where(known, 2.0 * np.nan_to_num(bits) - 1.0, 0.0)


def correlate_shifts(camera_code: np.ndarray, fine_code: np.ndarray, decimation: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Correlation ``r(shift)`` and overlap ``N(shift)`` for every shift with any overlap.

    Returns
    -------
    shifts, r, n : ndarray
        ``shifts`` from ``-decimation * (M - 1)`` to ``L - 1`` (``M`` frames, ``L`` fine samples).
    """
    from scipy.signal import correlate

    frames, fine = camera_code.size, fine_code.size
    spread = np.zeros(decimation * (frames - 1) + 1)
    spread[::decimation] = camera_code
    r = np.rint(correlate(fine_code, spread, mode="full", method="fft"))
    n = np.rint(correlate(np.ones(fine), np.abs(spread), mode="full", method="fft"))
    shifts = np.arange(-(spread.size - 1), fine)
    return shifts, r, n


def synchronise(camera_bits: np.ndarray, fine_bits: np.ndarray, *, decimation: int = 10,
                min_confidence: float = 0.5, min_peak_ratio: float = 1.5,
                min_overlap: int = 250, exclusion: int | None = None) -> SyncResult:
    """Find the shift aligning the camera's LED bits with the fine LED output (module notes).

    Parameters
    ----------
    camera_bits : array_like
        One bit per camera frame (0/1; NaN: unknown frame).
    fine_bits : array_like
        The LED output at the fine rate (0/1, complete).
    decimation : int
        Fine samples per camera frame (500 Hz / 50 fps = 10).
    min_confidence : float
        Refuse below this normalised correlation.
    min_peak_ratio : float
        Refuse when ``best / second_best`` is below this.
    min_overlap : int
        Frames (with known bits) that must meet fine samples (default 250 = 5 s at 50 fps).
    exclusion : int, optional
        Fine samples around the peak not counted as competitors (default ``2 * decimation``).

    Returns
    -------
    SyncResult

    Raises
    ------
    SyncError
        Not a bit sequence, too short an overlap, low confidence or no unique peak.
    """
    shifts, rho, n, usable = _correlation(camera_bits, fine_bits, decimation, min_overlap)
    best_value = float(np.nanmax(rho))
    tied = np.flatnonzero(rho >= best_value - 1e-12)
    best = int(tied[len(tied) // 2])
    exclusion = 2 * decimation if exclusion is None else int(exclusion)
    far = usable & (np.abs(shifts - shifts[best]) > exclusion)
    second = float(np.nanmax(rho[far])) if far.any() else -1.0
    confidence = min(max(best_value, 0.0), 1.0)
    ratio = confidence / second if second > 0.0 else math.inf
    shift = int(shifts[best])
    lag, phase = divmod(shift, decimation)
    result = SyncResult(shift, phase, lag, confidence, second, ratio, int(n[best]), len(tied),
                        decimation, shifts, rho)
    _refuse_unless_accepted(result, shifts[tied], exclusion, min_confidence, min_peak_ratio)
    return result


def _correlation(camera_bits: np.ndarray, fine_bits: np.ndarray, decimation: int,
                 min_overlap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Shifts, normalised correlation (NaN where the overlap is short), overlaps, usable mask."""
    if decimation < 1:
        raise SyncError(f"decimation = {decimation}: must be >= 1")
    camera = _code(camera_bits, "camera LED bits", allow_unknown=True)
    fine = _code(fine_bits, "fine LED bits", allow_unknown=False)
    known = int(np.count_nonzero(camera))
    if known < min_overlap:
        raise SyncError(f"camera LED: {known} known bits, fewer than min_overlap = "
                        f"{min_overlap} frames: too short to synchronise")
    shifts, r, n = correlate_shifts(camera, fine, decimation)
    usable = n >= min_overlap
    if not usable.any():
        raise SyncError(f"overlap too short: at best {int(n.max())} camera frames meet the "
                        f"{fine.size} fine samples, min_overlap = {min_overlap}")
    return shifts, np.where(usable, r / np.maximum(n, 1.0), np.nan), n, usable


def _refuse_unless_accepted(result: SyncResult, tied_shifts: np.ndarray, exclusion: int,
                            min_confidence: float, min_peak_ratio: float) -> None:
    """Raise :class:`SyncError` for a peak that is not unique, too weak or not clear enough."""
    confidence, ratio = result.confidence, result.peak_ratio
    numbers = (f"best shift {result.shift} fine samples (lag {result.lag}, phase "
               f"{result.phase}), confidence {confidence:.3f}, second best "
               f"{result.second_best:.3f} at more than {exclusion} samples away, peak ratio "
               f"{ratio:.2f}, overlap {result.overlap} frames")
    if tied_shifts.size > 1 and np.ptp(tied_shifts) >= tied_shifts.size:
        raise SyncError(f"no unique peak: {tied_shifts.size} separate shifts share the best "
                        f"correlation; {numbers}")
    if confidence < min_confidence:
        raise SyncError(f"confidence {confidence:.3f} below min_confidence = {min_confidence}: "
                        f"the sequences do not match; {numbers}")
    if ratio < min_peak_ratio:
        raise SyncError(f"peak not clearly unique: ratio {ratio:.2f} below min_peak_ratio = "
                        f"{min_peak_ratio}; {numbers}")
