"""EN 50318 statistics of the contact force over the analysed section.

EN 50318 ("Current collection systems - Validation of simulation of the dynamic interaction
between pantograph and overhead contact line") judges a simulation tool by a handful of numbers
computed over the analysed section of the line (the two central spans of a ten-span model in
the 2002 reference case, ``reference/catenary_en50318.md`` [recall]):

=================  ==================================================================
``mean``           :math:`F_m = \\overline{F_f}` - mean of the filtered contact force (N)
``std``            :math:`\\sigma = \\sqrt{\\overline{(F_f - F_m)^2}}` (N, population form)
``stat_max``       :math:`F_m + 3\\sigma` (N)
``stat_min``       :math:`F_m - 3\\sigma` (N)
``max``, ``min``   actual maximum / minimum of the filtered force :math:`F_f` (N)
``uplift_max_mm``  maximum uplift of the contact wire at the supports (steady arms) of
                   the analysed section over the run (mm)
``loss_pct``       percentage of contact loss (%)
=================  ==================================================================

Filter
    :math:`F_f` is the raw contact force low-pass filtered at 20 Hz (EN 50318, [recall]) with a
    **4th-order Butterworth filter applied forward and backward** (``scipy.signal.sosfiltfilt``):
    zero phase, magnitude :math:`|H(f)|^2 = 1 / (1 + (f/f_c)^{8})` (an 8th-order magnitude
    response; -6 dB at :math:`f_c`). The whole run is filtered and then cut to the section, so
    the filter's start-up transient stays outside the statistics.

Contact loss
    The fraction of **time** samples in the section at which the *raw* (unfiltered) contact
    force is zero (or negative, which a unilateral contact never gives), in percent. At the
    constant running speed of a co-simulation the fraction of time equals the fraction of
    distance. The filtered force is not used for it: filtering smears a loss of a few
    milliseconds into a dip that stays above zero.

All statistics need a uniformly sampled force (the co-simulation's communication step).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

#: Cut-off frequency of the EN 50318 low-pass filter (Hz) [recall].
CUTOFF_HZ = 20.0
#: Order of the Butterworth filter applied forward and backward (zero phase).
FILTER_ORDER = 4
#: The keys of :meth:`ContactStatistics.to_dict`, in the order of EN 50318's tables.
STATISTIC_KEYS = ("mean", "std", "stat_max", "stat_min", "max", "min", "uplift_max_mm",
                  "loss_pct")


@dataclass(frozen=True)
class ContactStatistics:
    """EN 50318 statistics of one run (see module notes for the definitions).

    Attributes
    ----------
    mean, std, stat_max, stat_min, max, min : float
        Contact-force statistics of the filtered force (N).
    uplift_max_mm : float
        Maximum uplift at the supports of the analysed section (mm); NaN if not given.
    loss_pct : float
        Contact loss, percent of the time in the section with zero raw force.
    samples : int
        Number of force samples in the section.
    cutoff_hz : float
        Low-pass cut-off (Hz).
    filter_order : int
        Butterworth order (applied forward and backward).
    """

    mean: float
    std: float
    stat_max: float
    stat_min: float
    max: float
    min: float
    uplift_max_mm: float
    loss_pct: float
    samples: int
    cutoff_hz: float = CUTOFF_HZ
    filter_order: int = FILTER_ORDER

    def to_dict(self) -> dict[str, float]:
        """The eight EN 50318 statistics by their keys (:data:`STATISTIC_KEYS`)."""
        values = asdict(self)
        return {key: float(values[key]) for key in STATISTIC_KEYS}

    def details(self) -> dict[str, float | int]:
        """How they were computed (samples, filter)."""
        return {"samples": self.samples, "cutoff_hz": self.cutoff_hz,
                "filter": f"Butterworth order {self.filter_order}, forward-backward (sosfiltfilt)",
                "loss_definition": "fraction of time samples with zero raw force"}


def sample_rate(time: np.ndarray) -> float:
    """Sampling rate (Hz) of a uniformly sampled time vector; refuses a non-uniform one."""
    time = np.asarray(time, dtype=float)
    if time.ndim != 1 or time.size < 2:
        raise ValueError(f"time must be a 1-D array of at least 2 samples, got shape {time.shape}")
    steps = np.diff(time)
    step = float(np.mean(steps))
    if not step > 0.0 or np.max(np.abs(steps - step)) > 1e-6 * step + 1e-12:
        raise ValueError("the contact force must be sampled uniformly in time "
                         f"(steps from {steps.min():g} to {steps.max():g} s)")
    return 1.0 / step


def lowpass_filter(force: np.ndarray, rate_hz: float, *, cutoff_hz: float = CUTOFF_HZ,
                   order: int = FILTER_ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass filter (forward-backward, ``sosfiltfilt``).

    Parameters
    ----------
    force : array_like
        Uniformly sampled signal.
    rate_hz : float
        Its sampling rate (Hz); must exceed twice `cutoff_hz`.
    cutoff_hz : float, optional
        Cut-off (Hz), default 20 Hz.
    order : int, optional
        Butterworth order of one pass (default 4): :math:`|H|^2 = 1/(1 + (f/f_c)^{4 n})`.

    Returns
    -------
    numpy.ndarray
        The filtered signal, same length (edges padded by odd reflection over three
        periods of the cut-off).
    """
    force = np.asarray(force, dtype=float)
    if not rate_hz > 2.0 * cutoff_hz:
        raise ValueError(f"sampling rate {rate_hz:g} Hz is too low for a {cutoff_hz:g} Hz filter")
    sos = signal.butter(order, cutoff_hz, btype="low", fs=rate_hz, output="sos")
    # pad by odd reflection over three periods of the cut-off, so the edges settle
    padding = min(force.size - 1, int(3.0 * rate_hz / cutoff_hz))
    return signal.sosfiltfilt(sos, force, padlen=max(padding, 0))


def compute_statistics(time: np.ndarray, force: np.ndarray, *,
                       section: np.ndarray | None = None,
                       support_uplift: np.ndarray | None = None,
                       cutoff_hz: float = CUTOFF_HZ,
                       filter_order: int = FILTER_ORDER) -> ContactStatistics:
    """EN 50318 statistics of a contact-force record.

    Parameters
    ----------
    time : array_like, shape (n,)
        Uniform time samples (s).
    force : array_like, shape (n,)
        Raw contact force (N), zero during contact loss.
    section : array_like of bool, shape (n,), optional
        Samples that belong to the analysed section (default: all). The filter runs over the
        whole record first.
    support_uplift : array_like, shape (m, k) or (k,), optional
        Uplift (m) of the contact wire at the k supports of the analysed section, at m times
        (or already the maximum per support). Its maximum, in mm, is ``uplift_max_mm``.
    cutoff_hz, filter_order
        The low-pass filter (see :func:`lowpass_filter`).

    Returns
    -------
    ContactStatistics
    """
    force = np.asarray(force, dtype=float)
    time = np.asarray(time, dtype=float)
    if force.shape != time.shape:
        raise ValueError(f"force has shape {force.shape}, time has {time.shape}")
    if not np.all(np.isfinite(force)):
        raise ValueError("the contact force has non-finite samples")
    mask = np.ones(force.shape, bool) if section is None else np.asarray(section, dtype=bool)
    if mask.shape != force.shape or not mask.any():
        raise ValueError("the analysed section selects no samples (or has the wrong shape)")
    filtered = lowpass_filter(force, sample_rate(time), cutoff_hz=cutoff_hz,
                              order=filter_order)[mask]
    mean, std = float(np.mean(filtered)), float(np.std(filtered))
    uplift = math.nan
    if support_uplift is not None and np.size(support_uplift):
        uplift = 1000.0 * float(np.max(support_uplift))
    loss = 100.0 * float(np.count_nonzero(force[mask] <= 0.0)) / int(mask.sum())
    return ContactStatistics(mean=mean, std=std, stat_max=mean + 3.0 * std,
                             stat_min=mean - 3.0 * std, max=float(filtered.max()),
                             min=float(filtered.min()), uplift_max_mm=uplift, loss_pct=loss,
                             samples=int(mask.sum()), cutoff_hz=cutoff_hz,
                             filter_order=filter_order)


__all__ = ["ContactStatistics", "compute_statistics", "lowpass_filter", "sample_rate",
           "STATISTIC_KEYS", "CUTOFF_HZ", "FILTER_ORDER"]
