"""The bellow's pressure supply: proportional valve and bellow, as the virtual test bed's plant.

The rig's valve takes 10 bar supply and delivers 0 to 7.5 bar for a control voltage of 0 to 24 V;
its input/output behaviour is nonlinear, and the bellow "approximately acts as a first-order
low-pass element" (thesis section 3.1). The thesis gives no numbers for the curve or the lag, so
the shape below is a project choice:

- static characteristic :math:`p_\\infty(u)`: zero in a dead band :math:`u \\le u_0`, saturated at
  :math:`p_\\mathrm{max}` for :math:`u \\ge u_1`, and in between the monotonic, concave curve

  .. math:: p_\\infty(u) = p_\\mathrm{max} \\big(1 - (1 - x)^{\\gamma}\\big), \\quad
            x = \\frac{u - u_0}{u_1 - u_0};

- dynamics: a transport delay :math:`t_d` and a first-order lag,
  :math:`\\tau \\dot p = p_\\infty(u(t - t_d)) - p`, with a separate time constant when venting.

:class:`ValvePlant` steps it with the exact zero-order-hold solution
:math:`p_{k+1} = p_\\infty + (p_k - p_\\infty) e^{-\\Delta t / \\tau}`.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

PROVENANCE = ("project choice: the thesis (section 3.1) reports 0-24 V -> 0-7.5 bar from a 10 bar "
              "supply, a nonlinearity and a first-order behaviour, without numbers")


@dataclass(frozen=True, kw_only=True)
class ValveParameters:
    """Valve and bellow parameters (SI except pressures in bar, as in the thesis).

    Parameters
    ----------
    supply_pressure : float
        Supply [bar] (10 bar; an upper bound for every pressure).
    max_pressure : float
        Output at full voltage [bar] (7.5 bar).
    max_voltage : float
        Full-scale control voltage [V] (24 V).
    dead_band : float
        :math:`u_0` [V]: below it the valve stays closed.
    saturation_voltage : float
        :math:`u_1` [V]: above it the output stays at `max_pressure`.
    exponent : float
        :math:`\\gamma \\ge 1`, the curvature of the characteristic (1 = linear).
    time_constant : float
        :math:`\\tau` [s] when filling.
    vent_time_constant : float or None
        :math:`\\tau` [s] when venting (None: same as filling).
    delay : float
        Transport delay :math:`t_d` [s].
    provenance : str
        Where the numbers come from.
    """

    supply_pressure: float = 10.0
    max_pressure: float = 7.5
    max_voltage: float = 24.0
    dead_band: float = 1.5
    saturation_voltage: float = 22.5
    exponent: float = 1.6
    time_constant: float = 0.4
    vent_time_constant: float | None = 0.5
    delay: float = 0.02
    provenance: str = PROVENANCE

    def __post_init__(self) -> None:
        checks = [
            ("max_pressure", 0.0 < self.max_pressure <= self.supply_pressure,
             f"must lie in (0, supply_pressure = {self.supply_pressure}] bar"),
            ("dead_band", 0.0 <= self.dead_band < self.saturation_voltage,
             "must be >= 0 V and below saturation_voltage"),
            ("saturation_voltage", self.saturation_voltage <= self.max_voltage,
             f"must be <= max_voltage = {self.max_voltage} V"),
            ("exponent", self.exponent >= 1.0, "must be >= 1"),
            ("time_constant", self.time_constant > 0.0, "must be > 0 s"),
            ("vent_time_constant", self.vent_time_constant is None
             or self.vent_time_constant > 0.0, "must be > 0 s or None"),
            ("delay", self.delay >= 0.0, "must be >= 0 s"),
        ]
        for name, ok, problem in checks:
            if not ok:
                raise ValueError(f"{name} = {getattr(self, name)!r}: {problem}")

    def static_pressure(self, voltage: float | np.ndarray) -> float | np.ndarray:
        """Steady-state output :math:`p_\\infty(u)` [bar] for a voltage [V] (clamped to 0..max)."""
        u = np.clip(voltage, 0.0, self.max_voltage)
        x = np.clip((u - self.dead_band) / (self.saturation_voltage - self.dead_band), 0.0, 1.0)
        return self.max_pressure * (1.0 - (1.0 - x) ** self.exponent)

    def voltage_for(self, pressure: float | np.ndarray) -> float | np.ndarray:
        """Inverse characteristic: the least voltage [V] whose steady output is `pressure`."""
        fraction = np.clip(np.asarray(pressure, dtype=float) / self.max_pressure, 0.0, 1.0)
        x = 1.0 - (1.0 - fraction) ** (1.0 / self.exponent)
        return self.dead_band + x * (self.saturation_voltage - self.dead_band)


class ValvePlant:
    """Streaming valve + bellow: :meth:`step` takes the voltage held over ``dt`` and returns p.

    Parameters
    ----------
    parameters : ValveParameters, optional
    initial_pressure : float
        Bellow pressure at the start [bar]; the delay line is filled with the voltage that holds
        it, so the plant starts at rest.

    Examples
    --------
    >>> plant = ValvePlant(initial_pressure=0.0)
    >>> pressures = [plant.step(24.0, 0.002) for _ in range(5000)]   # 10 s at full voltage
    >>> round(pressures[-1], 6)
    7.5
    """

    def __init__(self, parameters: ValveParameters | None = None, *,
                 initial_pressure: float = 0.0) -> None:
        self.parameters = parameters or ValveParameters()
        p = self.parameters
        if not 0.0 <= initial_pressure <= p.max_pressure:
            raise ValueError(f"initial_pressure = {initial_pressure!r}: must lie in "
                             f"[0, {p.max_pressure}] bar")
        self.pressure = float(initial_pressure)
        self.time = 0.0
        # (time at which the voltage was applied, voltage): the delay line
        self._applied: deque[tuple[float, float]] = deque(
            [(-math.inf, float(p.voltage_for(initial_pressure)))])

    def _delayed_voltage(self) -> float:
        """The voltage applied at ``time - delay`` (zero-order hold between steps)."""
        horizon = self.time - self.parameters.delay
        while len(self._applied) > 1 and self._applied[1][0] <= horizon + 1e-12:
            self._applied.popleft()
        return self._applied[0][1]

    def step(self, voltage: float, dt: float) -> float:
        """Apply `voltage` [V] for `dt` [s] and return the pressure [bar] at the end."""
        if not dt > 0.0:
            raise ValueError(f"dt = {dt!r}: must be > 0 s")
        if not math.isfinite(voltage):
            raise ValueError(f"voltage = {voltage!r}: must be finite")
        p = self.parameters
        self._applied.append((self.time, float(voltage)))
        target = _static_pressure(p, self._delayed_voltage())
        tau = p.time_constant
        if target < self.pressure and p.vent_time_constant is not None:
            tau = p.vent_time_constant
        self.pressure = target + (self.pressure - target) * math.exp(-dt / tau)
        self.time += dt
        return self.pressure


def _static_pressure(p: ValveParameters, voltage: float) -> float:
    """:meth:`ValveParameters.static_pressure` of one voltage in plain floats (the same IEEE
    operations as NumPy's scalars, without their per-call cost: 500 calls per second of a run)."""
    u = min(max(float(voltage), 0.0), p.max_voltage)
    x = min(max((u - p.dead_band) / (p.saturation_voltage - p.dead_band), 0.0), 1.0)
    return p.max_pressure * (1.0 - (1.0 - x) ** p.exponent)
