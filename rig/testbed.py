"""The virtual test bed's plant: the pantograph FMU on the emulated rig, sampled at 500 Hz.

What is simulated, per 2 ms sample (thesis chapter 3, Fig. 3.1):

- the linear motor's slider position ``s`` comes from the drive emulator (up positive, zero at
  the bar height `motor_zero_height`); the stator rides on a robot mode ``z`` (mass-spring-damper
  driven by the reaction of the slider and the bar), so the bar is at ``eta = h0 + s + z``;
- the valve voltage from the pressure controller drives :class:`panto.rig.pneumatics.ValvePlant`
  (what the pressure sensor measures); the bellow sees that pressure through a further transport
  delay and first-order lag;
- the pantograph FMU (Co-Simulation, one step per sample, inputs ``eta`` and ``p``) gives the
  contact force, the cross-bar and head heights;
- the force sensor sits between slider and bar: ``F_sensor = F_c - m_bar a_bar`` (gravity tared),
  plus offset, noise and quantisation; two laser sensors see the cross bar with noise.

The truth (every hidden quantity) is kept beside the measurements; a dataset records it in its
metadata for tests, never for the diagnosis.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from panto.build_fmu.stepping import FmuStepper
from panto.rig.imperfections import RigImperfections
from panto.rig.pneumatics import ValveParameters, ValvePlant

#: Sensor channels of a sample, with units.
SENSOR_UNITS = {"force": "N", "pressure": "bar", "laser_1": "m", "laser_2": "m"}
#: Hidden quantities of a sample, with units.
TRUTH_UNITS = {"eta": "m", "contact_force": "N", "bellow_pressure": "bar",
               "measured_pressure": "bar", "y_cb": "m", "xi": "m", "x_cb": "m",
               "robot_displacement": "m", "slider_position": "m", "bar_acceleration": "m/s^2",
               "led": "1"}


@dataclass(frozen=True)
class PlantSample:
    """One 500 Hz sample of the plant: what the sensors read and what really happened."""

    time: float
    sensors: dict[str, float]
    truth: dict[str, float]


class _DelayedLag:
    """Transport delay followed by a first-order lag, exact for a signal held over each step."""

    def __init__(self, value: float, lag: float, delay: float, dt: float) -> None:
        self.value = value
        self._decay = math.exp(-dt / lag) if lag > 0 else 0.0
        self._line: deque[float] = deque([value] * max(int(round(delay / dt)), 0))

    def step(self, value: float) -> float:
        if self._line:
            self._line.append(value)
            value = self._line.popleft()
        self.value = value + (self.value - value) * self._decay
        return self.value


class _RobotMode:
    """The robot's lightly damped mode under a force, integrated exactly for a held force."""

    def __init__(self, imperfections: RigImperfections, dt: float) -> None:
        self.enabled = imperfections.robot_compliance > 0
        self.z = self.v = 0.0
        if not self.enabled:
            return
        omega = 2 * math.pi * imperfections.robot_frequency
        zeta = imperfections.robot_damping_ratio
        self.compliance = imperfections.robot_compliance
        a = np.array([[0.0, 1.0], [-omega**2, -2 * zeta * omega]])
        from scipy.linalg import expm

        # Augmented exponential gives the zero-order-hold input matrix for u = compliance * F.
        aug = np.zeros((3, 3))
        aug[:2, :2], aug[1, 2] = a, omega**2
        phi = expm(aug * dt)
        self._phi, self._gamma = phi[:2, :2], phi[:2, 2]

    def step(self, force: float) -> tuple[float, float]:
        """Advance with `force` [N] (positive lifts the stator); return (z, acceleration)."""
        if not self.enabled:
            return 0.0, 0.0
        v_old = self.v
        state = self._phi @ np.array([self.z, self.v]) + self._gamma * self.compliance * force
        self.z, self.v = float(state[0]), float(state[1])
        return self.z, (self.v - v_old)


class VirtualTestBed:
    """The emulated rig's plant: pantograph FMU, bar, robot, bellow and sensors.

    Parameters
    ----------
    fmu_path : str or pathlib.Path
        The nonlinear pantograph FMU (``Pantograph.fmu``; any FMU with inputs ``eta``, ``p`` and
        outputs ``F_c``, ``y_cb``, ``xi`` works).
    parameters : mapping, optional
        Pantograph model parameters (the "true" pantograph). The imperfections that live in the
        model (friction, bellow angle, stiffening, unilateral contact) are added to them.
    imperfections : RigImperfections, optional
        Default: the rig as the thesis describes it.
    seed : int
        Seed of the sensor noise.
    sample_period : float
        500 Hz by default.
    motor_zero_height : float
        Bar height [m] when the slider is at 0.
    valve : ValveParameters, optional
        Valve and bellow supply.
    """

    def __init__(self, fmu_path: str | Path, *, parameters: Mapping[str, float] | None = None,
                 imperfections: RigImperfections | None = None, seed: int = 0,
                 sample_period: float = 0.002, motor_zero_height: float = 2.0,
                 valve: ValveParameters | None = None) -> None:
        self.imperfections = imperfections or RigImperfections()
        self.parameters = {**dict(parameters or {}), **self.imperfections.model_parameters()}
        self.sample_period = float(sample_period)
        self.motor_zero_height = float(motor_zero_height)
        self.valve_parameters = valve or ValveParameters()
        self.seed = seed
        self._fmu = FmuStepper(fmu_path, step_size=self.sample_period, inputs=("eta", "p"),
                               outputs=("F_c", "y_cb", "xi", "phi1", "delta"),
                               parameters={"start_in_equilibrium": True, **self.parameters})
        self._x_cb = _cross_bar_x(self.parameters)
        self.valve_voltage = 0.0
        self.led = 0
        self._history: deque[PlantSample] = deque(maxlen=16)
        self.keep_truth = True
        """Keep every sample's truth (for :meth:`truth_dataset`, e.g. the camera's view)."""
        self._truth_log: list[tuple[float, ...]] = []

    # --- life cycle ---------------------------------------------------------------------------

    def initialise(self, *, slider_position: float = 0.0, pressure: float = 4.0,
                   start_time: float = 0.0) -> PlantSample:
        """Start at rest: bar at the slider position, valve and bellow at `pressure` [bar]."""
        imp, dt = self.imperfections, self.sample_period
        self._rng = np.random.default_rng(self.seed)
        self._valve = ValvePlant(self.valve_parameters, initial_pressure=pressure)
        self.valve_voltage = float(self.valve_parameters.voltage_for(pressure))
        self._bellow = _DelayedLag(pressure, imp.bellow_lag, imp.bellow_delay, dt)
        self._robot = _RobotMode(imp, dt)
        self._slider = (slider_position, 0.0)
        self._eta = (self.motor_zero_height + slider_position,) * 2
        self._bellow_previous = pressure
        self._time = float(start_time)
        outputs = self._fmu.initialise([self._eta[-1], pressure], start_time=start_time)
        self._history.clear()
        self._truth_log.clear()
        sample = self._sample(outputs, pressure, pressure, bar_acceleration=0.0)
        self._keep(sample)
        return sample

    def close(self) -> None:
        self._fmu.close()

    def __enter__(self) -> "VirtualTestBed":
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    # --- the hooks of the drive emulator and of the I/O ---------------------------------------

    def write_valve_voltage(self, voltage: float) -> None:
        """The analogue output to the valve [V] (held until the next write)."""
        self.valve_voltage = float(voltage)

    def write_led(self, bit: int) -> None:
        """The digital output of the synchronisation LED."""
        self.led = 1 if bit else 0

    def load_force(self) -> float:
        """Force [N] the bar pushes up on the slider (for the drive's position loop)."""
        return self._history[-1].truth["contact_force"] if self._history else 0.0

    def on_slider_sample(self, time: float, position: float, velocity: float) -> PlantSample:
        """Advance the plant by one sample to `time` with the slider at `position` [m]."""
        imp, dt = self.imperfections, self.sample_period
        slider_acceleration = (velocity - self._slider[1]) / dt
        self._slider = (position, velocity)
        previous = self._history[-1]
        sensor_force = previous.truth["contact_force"] - imp.bar_mass * previous.truth["bar_acceleration"]
        # Reaction on the stator: the bar's force minus what accelerates the slider.
        z, _ = self._robot.step(sensor_force - imp.slider_mass * slider_acceleration)
        eta = self.motor_zero_height + position + z
        bar_acceleration = (eta - 2 * self._eta[-1] + self._eta[-2]) / dt**2
        self._eta = (self._eta[-1], eta)
        measured_pressure = self._valve.step(self.valve_voltage, dt)
        bellow = self._bellow.step(measured_pressure)
        # The plant moves continuously between samples: step it on the mean of the inputs over
        # the step (second-order accurate for inputs linear in time, as the models assume), then
        # read the outputs with the inputs at the end of the step (the contact force feeds eta
        # through). Holding the end value over the step would show the plant's states eta half a
        # sample early.
        self._fmu.step([0.5 * (self._eta[-2] + eta), 0.5 * (self._bellow_previous + bellow)])
        self._fmu.set_inputs([eta, bellow])
        outputs = self._fmu.outputs()
        self._bellow_previous = bellow
        self._time = float(time)
        sample = self._sample(outputs, measured_pressure, bellow, bar_acceleration)
        self._keep(sample)
        return sample

    def _keep(self, sample: PlantSample) -> None:
        self._history.append(sample)
        if self.keep_truth:
            self._truth_log.append((sample.time, *(sample.truth[n] for n in TRUTH_UNITS)))

    def truth_dataset(self, origin: float = 0.0):
        """Every sample's hidden quantities as a :class:`panto.rig.dataset.Dataset` (source emulator).

        Times are shifted by `origin` (the clock time of a run's t = 0), so they share the run's
        time base; samples before the run (the drive's start-up) have negative times.

        The camera's view (markers on pan-head, cross bar and slider; the LED) and the tests of
        the diagnosis read it; the diagnosis itself never does.
        """
        from panto.rig.dataset import Dataset, RunMetadata

        log = np.array(self._truth_log, dtype=float)
        log = log[np.concatenate([[True], np.diff(log[:, 0]) > 0])]  # one row per instant
        return Dataset(log[:, 0] - origin, {n: log[:, i + 1] for i, n in enumerate(TRUTH_UNITS)},
                       dict(TRUTH_UNITS),
                       RunMetadata(sample_rate=1.0 / self.sample_period, source="emulator",
                                   notes="virtual test bed truth: never an input to the diagnosis",
                                   truth=self.truth_record()))

    def read_sensors(self, now: float) -> dict[str, float]:
        """The sensor values of :meth:`read` (the :class:`panto.rig.session.RigIO` interface)."""
        return self.read(now).sensors

    def read(self, now: float | None = None) -> PlantSample:
        """The latest sample at or before `now` (the last one if `now` is None)."""
        if now is not None:
            for sample in reversed(self._history):
                if sample.time <= now + 1e-9:
                    return sample
        return self._history[-1]

    # --- measurement --------------------------------------------------------------------------

    def _sample(self, outputs: np.ndarray, measured_pressure: float, bellow: float,
                bar_acceleration: float) -> PlantSample:
        imp = self.imperfections
        contact_force, y_cb, xi, phi1, delta = (float(v) for v in outputs)
        noise = self._rng.standard_normal(4)
        force = contact_force - imp.bar_mass * bar_acceleration
        sensors = {
            "force": _quantise(force + imp.force_offset + imp.force_noise * noise[0], imp.force_quantum),
            "pressure": _quantise(measured_pressure + imp.pressure_offset + imp.pressure_noise * noise[1],
                                  imp.pressure_quantum),
            "laser_1": _quantise(y_cb + imp.laser_offset + imp.laser_noise * noise[2], imp.laser_quantum),
            "laser_2": _quantise(y_cb + imp.laser_offset + imp.laser_noise * noise[3], imp.laser_quantum),
        }
        truth = {"eta": self._eta[-1], "contact_force": contact_force, "bellow_pressure": bellow,
                 "measured_pressure": measured_pressure, "y_cb": y_cb, "xi": xi,
                 "x_cb": self._x_cb(phi1, delta), "robot_displacement": self._robot.z,
                 "slider_position": self._slider[0], "bar_acceleration": bar_acceleration,
                 "led": float(self.led)}
        return PlantSample(self._time, sensors, truth)

    def markers(self, sample: PlantSample | None = None) -> dict[str, tuple[float, float]]:
        """True (x, y) positions [m] of the camera markers: pan-head, cross bar, slider (bar)."""
        truth = (sample or self._history[-1]).truth
        return {"pan_head": (truth["x_cb"], truth["xi"]),
                "cross_bar": (truth["x_cb"], truth["y_cb"]),
                "slider": (truth["x_cb"], truth["eta"])}

    def truth_record(self) -> dict[str, Any]:
        """What generated the data, for a dataset's metadata (never read by the diagnosis)."""
        return {"imperfections": self.imperfections.to_dict(),
                "pantograph_parameters": dict(self.parameters),
                "valve": {k: getattr(self.valve_parameters, k) for k in
                          ("max_pressure", "dead_band", "saturation_voltage", "exponent",
                           "time_constant", "vent_time_constant", "delay")},
                "motor_zero_height": self.motor_zero_height, "noise_seed": self.seed}


def _quantise(value: float, quantum: float) -> float:
    return round(value / quantum) * quantum if quantum > 0 else value


def _cross_bar_x(parameters: Mapping[str, float]):
    """x_cb(phi1, delta) of the linkage (eq. 2.13) with the given geometry."""
    from panto.fmu_src.models import default_parameters

    values = {**default_parameters("Pantograph").values, **parameters}
    geometry = tuple((n, type(values[n]).__name__, values[n]) for n in _cross_bar_expression()[1])
    function = _cross_bar_function(geometry)
    return lambda phi1, delta: float(function(phi1, delta))


@lru_cache(maxsize=1)
def _cross_bar_expression():
    """(x_cb with phi2 substituted, names of its geometry symbols): the symbolic part of
    :func:`_cross_bar_x`, built once per process (it costs 0.4 s)."""
    from panto.fmu_src.pantograph import linkage

    kin = linkage()
    x_cb = kin["x_cb"].subs(kin["phi2"], kin["phi2_expr"])
    names = tuple(sorted(s.name for s in x_cb.free_symbols if s.name not in ("phi1", "delta")))
    return x_cb, names, kin["phi1"], kin["delta"]


@lru_cache(maxsize=32)
def _cross_bar_function(geometry: tuple[tuple[str, str, float], ...]):
    """x_cb(phi1, delta) lambdified for one geometry ``((name, type name, value), ...)``."""
    import sympy as sp

    x_cb, _, phi1, delta = _cross_bar_expression()
    symbols = {s.name: s for s in x_cb.free_symbols}
    fixed = {symbols[n]: value for n, _, value in geometry}
    return sp.lambdify((phi1, delta), x_cb.subs(fixed), "math")
