"""The rig's limits on the designed inputs, its profile files and the conventional input.

Shared by the designs of :mod:`panto.identification.design.pantograph`, their online and
discrimination variants and the profile writer :mod:`panto.identification.design.profiles`:

* :class:`RigInputConstraints`: amplitude, speed and acceleration of the linear motor, the pressure
  demand's range and lag, the design's sampling (thesis section 5.5), read from a rig profile, the
  drive and the pressure loop by :meth:`RigInputConstraints.from_rig`;
* :func:`profile_path`: a rig profile by path or by name;
* :func:`conventional_inputs`: the APRBS training profile (thesis 4.2) as the rig plays it, the
  input a design is compared with.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

import panto.rig
from panto.identification.design.pantograph_sensitivity import PressureLag, pressure_lag_from_rig
from panto.rig.conditioning import MotorConditioner, following_error_bound
from panto.rig.drive_emulator import DriveParameters
from panto.rig.profiles import load_profile, render_profile


@dataclass(frozen=True)
class RigInputConstraints:
    """The rig's limits on both inputs and the design's sampling (SI; pressure in bar).

    Parameters
    ----------
    motor_min, motor_max : float
        Motor position range about mid-stroke [m].
    motor_speed, motor_acceleration : float
        :math:`v_\\max` [m/s] and :math:`a_\\max` [m/s^2] of the motor position.
    pressure_min, pressure_max : float
        Pressure demand range [bar] (>= 3.4 bar: the test pantograph carries its arms).
    pressure_start : float
        Pressure at rest before and at the start of the run [bar] (the profile offset).
    pressure_lag : PressureLag
        Demand -> measured pressure.
    motor_zero_height : float
        Model input :math:`\\eta` at motor position 0 [m].
    sample_period : float
        Design sample period [s] (the identification's 50 Hz).
    motor_hold, pressure_hold : float
        Hold time of a designed level [s].
    minimum_contact_force : float or None
        Least predicted contact force [N]; None: no contact constraint.
    """

    motor_min: float = -0.13
    motor_max: float = 0.13
    motor_speed: float = 1.25
    motor_acceleration: float = 20.0
    pressure_min: float = 3.4
    pressure_max: float = 6.0
    pressure_start: float = 4.0
    pressure_lag: PressureLag = field(default_factory=lambda: PressureLag(0.22, 0.02))
    motor_zero_height: float = 2.0
    sample_period: float = 0.02
    motor_hold: float = 0.1
    pressure_hold: float = 0.5
    minimum_contact_force: float | None = 20.0

    def __post_init__(self) -> None:
        checks = [("motor_max", self.motor_min < 0.0 < self.motor_max, "need motor_min < 0 < motor_max"),
                  ("motor_speed", self.motor_speed > 0, "must be > 0 m/s"),
                  ("motor_acceleration", self.motor_acceleration > 0, "must be > 0 m/s^2"),
                  ("pressure_start", self.pressure_min <= self.pressure_start <= self.pressure_max
                   and self.pressure_min < self.pressure_max, "need pressure_min <= "
                   "pressure_start <= pressure_max, pressure_min < pressure_max"),
                  ("sample_period", self.sample_period > 0, "must be > 0 s"),
                  ("motor_hold", self.motor_hold >= self.sample_period, "must be >= sample_period"),
                  ("pressure_hold", self.pressure_hold >= self.sample_period,
                   "must be >= sample_period")]
        for name, ok, problem in checks:
            if not ok:
                raise ValueError(f"RigInputConstraints.{name} = {getattr(self, name)!r}: {problem}")

    def describe(self) -> str:
        """The limits in one line with units (for progress lines and reports)."""
        force = "none" if self.minimum_contact_force is None else \
            f"{float(self.minimum_contact_force):g} N"
        return (f"motor {float(self.motor_min):g} .. {float(self.motor_max):g} m, "
                f"{float(self.motor_speed):g} m/s, {float(self.motor_acceleration):g} m/s^2; "
                f"pressure {float(self.pressure_min):g} .. {float(self.pressure_max):g} bar "
                f"(start {float(self.pressure_start):g} bar); holds >= {float(self.motor_hold):g} s "
                f"(motor), {float(self.pressure_hold):g} s (pressure); sample period "
                f"{float(self.sample_period):g} s; minimum contact force {force}")

    @property
    def smoothing_samples(self) -> int:
        """Moving-average length :math:`L = \\lceil 2 v_\\max / (a_\\max T) \\rceil` (>= 1)."""
        return max(1, math.ceil(2 * self.motor_speed / (self.motor_acceleration * self.sample_period)
                                - 1e-9))

    def hold_samples(self) -> tuple[int, int]:
        """Samples per motor level and per pressure level."""
        return (max(1, round(self.motor_hold / self.sample_period)),
                max(1, round(self.pressure_hold / self.sample_period)))

    def operating_point(self) -> tuple[float, float]:
        """:math:`(\\eta_0, p_0)` at rest: mid-stroke height and the start pressure."""
        return self.motor_zero_height, self.pressure_start

    def violations(self, motor: np.ndarray, demand: np.ndarray) -> dict[str, float]:
        """Largest violation of each limit (<= 0 when met) by motor positions and demands."""
        t = self.sample_period
        speed = np.diff(np.concatenate([[0.0], motor])) / t
        tol = 1e-9
        return {"motor_amplitude": float(max(np.max(motor) - self.motor_max,
                                             self.motor_min - np.min(motor))) - tol,
                "motor_speed": float(np.max(np.abs(speed)) - self.motor_speed) - tol,
                "motor_acceleration": float(np.max(np.abs(np.diff(np.concatenate([[0.0], speed])))
                                                   / t) - self.motor_acceleration) - tol,
                "pressure_range": float(max(np.max(demand) - self.pressure_max,
                                            self.pressure_min - np.min(demand))) - tol}

    @classmethod
    def from_rig(cls, profile: str = "aprbs_training", *, drive=None, valve=None, controller=None,
                 **overrides: Any) -> RigInputConstraints:
        """Limits from a rig profile, the drive and the pressure loop.

        Amplitude and pressure ranges and the start pressure from `profile`'s limits and offset;
        :math:`v_\\max` = the smaller of the limiter's speed (``motor_max_step`` per stream sample)
        and the speed at which :func:`panto.rig.conditioning.following_error_bound` for the drive's
        loop (triple pole at the position-loop bandwidth with velocity feed-forward) reaches
        the following-error warning; the pressure lag from :func:`pressure_lag_from_rig`.
        `overrides` replace any field.
        """
        rig = load_profile(profile_path(profile))
        drive = drive or DriveParameters()
        stream = 1.0 / rig.conditioning.sample_rate
        omega = 2 * math.pi * drive.position_loop_bandwidth_hz
        loop = ([3 * omega, 3 * omega ** 2, omega ** 3], [1, 3 * omega, 3 * omega ** 2, omega ** 3])
        per_speed = following_error_bound(max_step=stream, sample_time=stream,
                                          delay_periods=drive.stream_delay_periods,
                                          closed_loop=loop)
        speed = min(rig.limits.motor_max_step / stream, drive.following_error_warning / per_speed)
        values = dict(motor_min=rig.limits.motor_min, motor_max=rig.limits.motor_max,
                      motor_speed=speed, pressure_min=rig.limits.pressure_min,
                      pressure_max=rig.limits.pressure_max, pressure_start=rig.pressure.offset,
                      pressure_lag=pressure_lag_from_rig(pressure=rig.pressure.offset,
                                                         valve=valve, controller=controller))
        return cls(**(values | overrides))


def profile_path(profile: str | Path) -> Path:
    """A profile file: a path, or the name of one of the rig's profiles (``aprbs_training``)."""
    path = Path(profile)
    if path.suffix == ".json" or path.exists():
        return path
    return Path(panto.rig.__file__).parent / "profiles" / f"{profile}.json"


def conventional_inputs(n_samples: int, constraints: RigInputConstraints, *,
                        profile: str = "aprbs_training",
                        seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The APRBS training profile of equal length as the rig plays it, at the design period.

    The profile is rendered for ``n_samples`` design samples, the motor demand conditioned
    (:class:`panto.rig.conditioning.MotorConditioner`: its 4 Hz reference filter, fade-in and limiter,
    at the 250 Hz stream) and both channels are sampled at the design period. Returns motor
    positions [m] and pressure demands [bar].
    """
    rig = load_profile(profile_path(profile))
    rig = replace(rig, duration=n_samples * constraints.sample_period,
                  seed=rig.seed if seed is None else seed)
    rendered = render_profile(rig)
    every = int(round(rig.sample_rate / rig.conditioning.sample_rate))
    stream = slice(None, None, every)
    chain = MotorConditioner(rig.conditioning, rig.limits.motor_limits(), initial_position=0.0)
    command = chain.apply(rendered.motor_offset[stream], rendered.motor_dynamic[stream]).command
    step = int(round(constraints.sample_period * rig.conditioning.sample_rate))
    pick = int(round(constraints.sample_period * rig.sample_rate))
    return command[::step][:n_samples], rendered.pressure_demand[::pick][:n_samples]
