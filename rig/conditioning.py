"""The conditioning chain from position demand to linear-motor command (thesis Figs. 3.5-3.6).

Per 250 Hz stream sample :math:`k` (sample time :math:`T = 4` ms), with the demand split into an
offset :math:`o_k` and a dynamic part :math:`d_k`:

1. optional reference low-pass filter of the dynamic part, :math:`\\tilde d = F(z) d` (a
   second-order Butterworth biquad, cut-off ``filter_cutoff``), started at rest;
2. the "dynamic values" soft blend: the dynamic part is multiplied by a first-order low-pass of a
   0/1 switch :math:`s_k`, :math:`g_k = \\alpha s_k + (1 - \\alpha) g_{k-1}`,
   :math:`\\alpha = 1 - e^{-T/\\tau}` (zero-order-hold discretisation of :math:`1/(\\tau s + 1)`),
   :math:`g_{-1} = 0`, so a run fades in and settings can change while :math:`s = 0` without a
   jump (thesis section 3.1); the offset is added after: :math:`r_k = o_k + g_k \\tilde d_k`;
3. the absolute position limits, :math:`\\bar r_k = \\min(\\max(r_k, x_\\mathrm{min}),
   x_\\mathrm{max})`;
4. the limiter of the position change per sample (thesis Fig. 3.6, 5 mm):
   :math:`c_k = c_{k-1} + \\mathrm{clip}(\\bar r_k - c_{k-1}, -\\Delta, \\Delta)`, :math:`c_{-1}` =
   the drive's actual position when the stream starts.

Guarantees (by induction over :math:`k`, with :math:`c_{-1}` inside the limits):
:math:`x_\\mathrm{min} \\le c_k \\le x_\\mathrm{max}` and :math:`|c_k - c_{k-1}| \\le \\Delta`, so
the command, interpolated linearly by the drive, never moves faster than
:math:`v_\\mathrm{max} = \\Delta / T = 5\\,\\mathrm{mm} / 4\\,\\mathrm{ms} = 1.25` m/s.

Why this prevents the drive's following-error fault (30 mm, thesis section 3.1): see
:func:`following_error_bound`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps


@dataclass(frozen=True, kw_only=True)
class ConditioningOptions:
    """Settings of the chain (thesis Fig. 3.5; the numbers are project defaults).

    Parameters
    ----------
    reference_filter : bool
        Low-pass filter the dynamic part before the blend.
    filter_cutoff : float
        Cut-off frequency of the reference filter [Hz], below the stream's Nyquist frequency.
    blend_time_constant : float
        Time constant :math:`\\tau` [s] of the low-pass on the "dynamic values" switch.
    limiter : bool
        Limit the position change per sample (switch off only to demonstrate the fault).
    sample_rate : float
        Rate of the position stream [Hz] (250 Hz on the rig).
    """

    reference_filter: bool = False
    filter_cutoff: float = 20.0
    blend_time_constant: float = 0.5
    limiter: bool = True
    sample_rate: float = 250.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_rate) and self.sample_rate > 0.0):
            raise ValueError(f"sample_rate = {self.sample_rate!r}: must be > 0 Hz")
        if not (0.0 < self.filter_cutoff < self.sample_rate / 2.0):
            raise ValueError(f"filter_cutoff = {self.filter_cutoff!r}: must lie in (0, "
                             f"{self.sample_rate / 2}) Hz")
        if not (math.isfinite(self.blend_time_constant) and self.blend_time_constant >= 0.0):
            raise ValueError(f"blend_time_constant = {self.blend_time_constant!r}: must be "
                             ">= 0 s")


@dataclass(frozen=True, kw_only=True)
class MotorLimits:
    """Absolute position range [m] and largest change per stream sample :math:`\\Delta` [m]."""

    position_min: float
    position_max: float
    max_step: float = 0.005

    def __post_init__(self) -> None:
        if not (math.isfinite(self.position_min) and math.isfinite(self.position_max)
                and self.position_min < self.position_max):
            raise ValueError(f"position_max = {self.position_max!r}: must be finite and above "
                             f"position_min = {self.position_min!r}")
        if not (math.isfinite(self.max_step) and self.max_step > 0.0):
            raise ValueError(f"max_step = {self.max_step!r}: must be > 0 m")


class ReferenceFilter:
    """Second-order Butterworth low-pass as a biquad in transposed direct form II, at rest."""

    def __init__(self, cutoff: float, sample_rate: float) -> None:
        self.sos = sps.butter(2, cutoff, fs=sample_rate, output="sos")
        self._state = [0.0, 0.0]

    def step(self, value: float) -> float:
        """Filter one sample."""
        b0, b1, b2, _, a1, a2 = (float(v) for v in self.sos[0])
        z0, z1 = self._state
        out = b0 * value + z0
        self._state = [b1 * value - a1 * out + z1, b2 * value - a2 * out]
        return out

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Filter a whole sequence from rest (scipy's ``sosfilt``; equals repeated :meth:`step`)."""
        return sps.sosfilt(self.sos, np.asarray(values, dtype=float))


class DynamicBlend:
    """The "dynamic values" gain: a first-order low-pass of the 0/1 switch, from :math:`g = 0`."""

    def __init__(self, time_constant: float, sample_rate: float) -> None:
        self.alpha = 1.0 if time_constant == 0.0 else -math.expm1(-1.0 / (time_constant
                                                                         * sample_rate))
        self.gain = 0.0

    def step(self, switch: float) -> float:
        """Advance the gain with the switch value and return it."""
        self.gain = self.alpha * switch + (1.0 - self.alpha) * self.gain
        return self.gain

    def apply(self, switch: np.ndarray) -> np.ndarray:
        """Gains for a whole switch sequence (``lfilter``; equals repeated :meth:`step`)."""
        return sps.lfilter([self.alpha], [1.0, -(1.0 - self.alpha)],
                           np.asarray(switch, dtype=float))


@dataclass(frozen=True)
class ConditionedSample:
    """One command: position [m] and whether the limiter or the position limits acted."""

    command: float
    limited: bool


@dataclass(frozen=True)
class ConditionedCommand:
    """A conditioned sequence: commands [m], blend gains and where the limiter acted."""

    command: np.ndarray
    gain: np.ndarray
    limited: np.ndarray


class MotorConditioner:
    """The chain of thesis Fig. 3.5 with the limiter of Fig. 3.6, streaming and vectorised.

    Parameters
    ----------
    options : ConditioningOptions
    limits : MotorLimits
    initial_position : float
        The drive's actual position when the stream starts [m] (:math:`c_{-1}`); clipped into
        the limits.

    Examples
    --------
    >>> limits = MotorLimits(position_min=0.0, position_max=0.3)
    >>> chain = MotorConditioner(ConditioningOptions(blend_time_constant=0.0), limits,
    ...                          initial_position=0.1)
    >>> round(chain.step(0.1, 0.02).command, 6)   # a 20 mm step is cut to 5 mm
    0.105
    """

    def __init__(self, options: ConditioningOptions, limits: MotorLimits, *,
                 initial_position: float) -> None:
        self.options, self.limits = options, limits
        self.initial_position = min(max(float(initial_position), limits.position_min),
                                    limits.position_max)
        self.reset()

    def reset(self) -> None:
        """Back to the start: filter at rest, gain 0, previous command = initial position."""
        opts = self.options
        self._filter = (ReferenceFilter(opts.filter_cutoff, opts.sample_rate)
                        if opts.reference_filter else None)
        self._blend = DynamicBlend(opts.blend_time_constant, opts.sample_rate)
        self.previous = self.initial_position

    @property
    def gain(self) -> float:
        """The present "dynamic values" gain (0 to 1)."""
        return self._blend.gain

    def _limit(self, target: float) -> tuple[float, bool]:
        lim = self.limits
        bounded = min(max(target, lim.position_min), lim.position_max)
        change = bounded - self.previous
        if self.options.limiter:
            change = min(max(change, -lim.max_step), lim.max_step)
        command = self.previous + change
        return command, command != target

    def step(self, offset: float, dynamic: float, switch: float = 1.0) -> ConditionedSample:
        """Condition one stream sample: offset and dynamic part of the demand [m], switch 0/1."""
        if self._filter is not None:
            dynamic = self._filter.step(float(dynamic))
        gain = self._blend.step(float(switch))
        command, limited = self._limit(float(offset) + gain * dynamic)
        self.previous = command
        return ConditionedSample(command, limited)

    def apply(self, offset: np.ndarray, dynamic: np.ndarray,
              switch: np.ndarray | None = None) -> ConditionedCommand:
        """Condition a whole sequence from the start (:meth:`reset` first); same as :meth:`step`.

        The filter and the blend run vectorised (scipy); the limiter is a recursion and runs
        sample by sample.
        """
        self.reset()
        dynamic = np.asarray(dynamic, dtype=float)
        offset = np.broadcast_to(np.asarray(offset, dtype=float), dynamic.shape)
        switch = np.ones(dynamic.shape) if switch is None else np.asarray(switch, dtype=float)
        if self._filter is not None:
            dynamic = self._filter.apply(dynamic)
        gain = self._blend.apply(switch)
        target = offset + gain * dynamic
        command = np.empty(target.shape)
        limited = np.zeros(target.shape, dtype=bool)
        for k, value in enumerate(target.tolist()):
            command[k], limited[k] = self._limit(value)
            self.previous = command[k]
        return ConditionedCommand(command, gain, limited)


def following_error_bound(*, max_step: float = 0.005, sample_time: float = 0.004,
                          delay_periods: float = 1.5, bandwidth: float | None = None,
                          closed_loop: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """Worst-case following error [m] of a drive tracking the limited command.

    With the limiter, the setpoints change by at most :math:`\\Delta` per period :math:`T`; the
    drive interpolates them linearly, so its reference :math:`r(t)` has
    :math:`|\\dot r| \\le v_\\mathrm{max} = \\Delta/T` (1.25 m/s for 5 mm at 250 Hz). The drive
    applies the reference after a delay :math:`d` (1.5 periods = 6 ms, the interpolation buffer)
    and tracks it with a position loop of closed-loop transfer function :math:`G(s)`. The error
    against the undelayed setpoint is :math:`e = (r(t) - r(t - d)) + (1 - G) r(t - d)`, hence for
    every input allowed by the limiter

    .. math:: |e(t)| \\le v_\\mathrm{max} \\Big(d + \\int_0^\\infty |1 - h(t)|\\,dt\\Big),

    with :math:`h` the unit-step response of :math:`G` (:math:`E = ((1 - G)/s) \\cdot s R` and the
    L1 norm of the impulse response of :math:`(1 - G)/s` is that integral). For a first-order
    loop of bandwidth :math:`\\omega_b` [rad/s] the integral is :math:`1/\\omega_b`. The
    following-error fault (30 mm) therefore cannot trip when this bound is below 30 mm, i.e. for
    a first-order loop when :math:`\\omega_b > v_\\mathrm{max} / (e_\\mathrm{max} - v_\\mathrm{max}
    d)` = 1.25 / (0.03 - 0.0075) = 55.6 rad/s (8.8 Hz) (see :func:`minimum_loop_bandwidth`); if
    the drive measures the error against its delayed, interpolated demand, the :math:`d` term
    drops and the bound is conservative. The drive must start at rest at the first command (the
    chain starts its limiter at the actual position).

    The bound assumes the loop stays linear. The limiter bounds the speed, not the
    acceleration: a reversal from +1.25 to -1.25 m/s within one period asks for
    :math:`2 v_\\mathrm{max}/T` = 625 m/s², i.e. 1.25 kN on a 2 kg slider; if the drive's force
    saturates there the error can exceed the linear bound (use the reference filter, or keep
    the motor force limit above :math:`m \\cdot 2 v_\\mathrm{max} / T`). Example: a loop with a
    triple pole at :math:`-2\\pi \\cdot 20` Hz and velocity feed-forward,
    :math:`G = (3\\omega s^2 + 3\\omega^2 s + \\omega^3)/(s + \\omega)^3`, gives 6.2 mm without
    the delay term and 13.7 mm with it.

    Parameters
    ----------
    max_step, sample_time : float
        Limiter step :math:`\\Delta` [m] and stream period :math:`T` [s].
    delay_periods : float
        Setpoint delay in periods (1.5 on the drive).
    bandwidth : float, optional
        First-order loop bandwidth :math:`\\omega_b` [rad/s].
    closed_loop : (num, den), optional
        Any stable continuous closed-loop transfer function with unit static gain instead.

    Returns
    -------
    float
        The bound [m].
    """
    speed = max_step / sample_time
    delay = delay_periods * sample_time
    if (bandwidth is None) == (closed_loop is None):
        raise ValueError("give exactly one of bandwidth and closed_loop")
    if bandwidth is not None:
        if not bandwidth > 0.0:
            raise ValueError(f"bandwidth = {bandwidth!r}: must be > 0 rad/s")
        return speed * (delay + 1.0 / bandwidth)
    system = sps.lti(*closed_loop)
    poles = np.asarray(system.poles)
    if poles.size == 0 or np.max(poles.real) >= 0.0:
        raise ValueError("closed_loop must be stable (all poles in the left half-plane)")
    horizon = 40.0 / float(np.min(np.abs(poles.real)))
    time = np.linspace(0.0, horizon, 200_001)
    _, step_response = sps.step(system, T=time)
    return speed * (delay + float(np.trapezoid(np.abs(1.0 - step_response), time)))


def minimum_loop_bandwidth(*, max_error: float = 0.030, max_step: float = 0.005,
                           sample_time: float = 0.004, delay_periods: float = 1.5) -> float:
    """Smallest first-order loop bandwidth [rad/s] for which :func:`following_error_bound` stays
    below `max_error` [m]: :math:`\\omega_b = v_\\mathrm{max} / (e_\\mathrm{max} -
    v_\\mathrm{max} d)`."""
    speed = max_step / sample_time
    room = max_error - speed * delay_periods * sample_time
    if room <= 0.0:
        raise ValueError(f"max_error = {max_error} m is used up by the delay alone")
    return speed / room
