"""The bellow pressure loop, controller side: a discrete PI controller with anti-windup.

The rig closed the loop around the valve with "a simple PI controller", because the valve's
voltage-to-pressure relation is nonlinear and its supply voltage could not be measured (thesis
section 3.1); the controller ran on the real-time unit at its 2 ms sample time and the user could
tune it. The output is the valve voltage, clamped to 0..24 V. With :math:`e_k = p^*_k - p_k`:

.. math:: v_k = K_p e_k + I_k, \\qquad u_k = \\mathrm{sat}_{[0, 24\\,\\mathrm{V}]}(v_k),

and the integrator :math:`I` is updated with one of

- ``"conditional"`` integration (clamping): :math:`I_{k+1} = I_k + K_i T e_k` unless the output is
  saturated and the error would drive it further into saturation;
- ``"back-calculation"``: :math:`I_{k+1} = I_k + T (K_i e_k + (u_k - v_k)/T_t)` with tracking time
  :math:`T_t` (Astrom & Hagglund, *Advanced PID Control*, ISA 2006, sec. 3.5);
- ``"none"``: plain integration, which winds up during saturation (for comparison only).

Gains are project defaults (the thesis gives none), tuned against :mod:`panto.rig.pneumatics`:
the integral time :math:`K_p/K_i` equals the bellow's time constant (0.4 s), the loop crossover is
a few rad/s, well below the phase loss of the 20 ms valve delay.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

ANTI_WINDUP_METHODS = ("conditional", "back-calculation", "none")


@dataclass(frozen=True, kw_only=True)
class PressureControllerOptions:
    """Settings of the PI loop.

    Parameters
    ----------
    kp : float
        Proportional gain [V/bar].
    ki : float
        Integral gain [V/(bar s)].
    sample_time : float
        Controller period [s] (2 ms, the real-time unit's).
    voltage_min, voltage_max : float
        Output range [V] (0 V and 24 V, the valve's input range).
    anti_windup : str
        ``"conditional"``, ``"back-calculation"`` or ``"none"``.
    tracking_time : float or None
        :math:`T_t` [s] for back-calculation (None: half the integral time
        :math:`T_i = K_p / K_i`).
    """

    kp: float = 4.0
    ki: float = 10.0
    sample_time: float = 0.002
    voltage_min: float = 0.0
    voltage_max: float = 24.0
    anti_windup: str = "conditional"
    tracking_time: float | None = None

    def __post_init__(self) -> None:
        for name in ("kp", "ki"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} = {value!r}: must be finite and >= 0")
        if not self.sample_time > 0.0:
            raise ValueError(f"sample_time = {self.sample_time!r}: must be > 0 s")
        if not self.voltage_min < self.voltage_max:
            raise ValueError(f"voltage_max = {self.voltage_max!r}: must exceed voltage_min = "
                             f"{self.voltage_min!r}")
        if self.anti_windup not in ANTI_WINDUP_METHODS:
            raise ValueError(f"anti_windup = {self.anti_windup!r}: must be one of "
                             f"{ANTI_WINDUP_METHODS}")
        if self.tracking_time is not None and not self.tracking_time > 0.0:
            raise ValueError(f"tracking_time = {self.tracking_time!r}: must be > 0 s")

    def effective_tracking_time(self) -> float:
        """:math:`T_t` [s] used by back-calculation."""
        if self.tracking_time is not None:
            return self.tracking_time
        return 0.5 * self.kp / self.ki if self.ki > 0.0 else math.inf


class PressureController:
    """Discrete PI pressure controller with anti-windup; one :meth:`step` per sample.

    Parameters
    ----------
    options : PressureControllerOptions, optional
    initial_voltage : float
        Output before the first step [V]; the integrator starts there (bumpless start).

    Examples
    --------
    >>> pi = PressureController(initial_voltage=12.0)
    >>> pi.step(demand=3.0, measured=3.0)   # no error: the output stays where it was
    12.0
    """

    def __init__(self, options: PressureControllerOptions | None = None, *,
                 initial_voltage: float = 0.0) -> None:
        self.options = options or PressureControllerOptions()
        self.reset(initial_voltage)

    def reset(self, voltage: float = 0.0) -> None:
        """Restart with the output at `voltage` [V] (clamped), e.g. when the loop is enabled."""
        opts = self.options
        self.integral = min(max(float(voltage), opts.voltage_min), opts.voltage_max)
        self.voltage = self.integral
        self.saturated = False

    def step(self, demand: float, measured: float) -> float:
        """One controller period: pressure demand and measurement [bar] -> valve voltage [V]."""
        if not (math.isfinite(demand) and math.isfinite(measured)):
            raise ValueError(f"demand = {demand!r}, measured = {measured!r}: must be finite")
        opts = self.options
        error = demand - measured
        unclamped = opts.kp * error + self.integral
        voltage = min(max(unclamped, opts.voltage_min), opts.voltage_max)
        self.saturated = voltage != unclamped
        increment = opts.ki * opts.sample_time * error
        if opts.anti_windup == "conditional":
            pushing_out = ((unclamped > opts.voltage_max and error > 0.0)
                           or (unclamped < opts.voltage_min and error < 0.0))
            if not pushing_out:
                self.integral += increment
        elif opts.anti_windup == "back-calculation":
            self.integral += increment + (opts.sample_time / opts.effective_tracking_time()
                                          * (voltage - unclamped))
        else:
            self.integral += increment
        self.voltage = voltage
        return voltage
