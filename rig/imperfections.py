"""The rig's imperfections that the virtual test bed adds to the pantograph model.

Each effect is one or two numbers; zero switches it off. :meth:`RigImperfections.none` is the ideal
rig (the nominal model measured perfectly), the default instance is the rig as the thesis
describes or implies it (chapter 3): the aluminium bar between force sensor and pantograph, the
linear motor on a robot, joints that stick, a bellow behind a hose, noisy lasers, sampled sensors.
The thesis gives no magnitudes for most of them; the defaults are project choices of a plausible
size, stated in :data:`PROVENANCE`, and every one is a parameter.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any, Mapping

#: Where each default comes from.
PROVENANCE: dict[str, str] = {
    "bar_mass": "thesis ch. 3: aluminium bar of about 1.5 kg between force sensor and pantograph",
    "robot_compliance": "project choice: the thesis' linear motor sits on an industrial robot (Fig. 3.1), "
                        "no modal data given",
    "hinge_friction_torque": "project choice: joint friction is not in the thesis model",
    "bellow_lag": "project choice: thesis 3.1 calls the bellow a first-order low-pass, no time constant",
    "bellow_delay": "project choice: hose between valve (pressure sensor) and bellow",
    "bellow_angle_coefficient": "project choice: a rolling bellow's effective lever changes with the angle",
    "unilateral_contact": "thesis ch. 3: large steps 'often lead to loss of contact'",
    "head_stiffening": "project choice: progressive head suspension springs",
    "force_noise": "project choice: amplifier noise of the six-axis force sensor",
    "laser_noise": "thesis 3.3: laser signals 'heavily corrupted by noise'",
    "laser_offset": "thesis 3.3: lasers aimed at the airfoils on the cross bar, a small offset",
    "quantisation": "project choice: 16-bit converters over the sensors' ranges (0-10 V inputs, thesis 3)",
}


@dataclass(frozen=True, kw_only=True)
class RigImperfections:
    """Magnitudes of the rig's imperfections (SI; pressures in bar as in the thesis).

    Parameters
    ----------
    bar_mass : float
        Mass [kg] of the bar between force sensor and pantograph; its inertia enters the force
        signal, ``F_sensor = F_c - bar_mass * a_bar`` (gravity tared).
    robot_compliance : float
        Static compliance [m/N] of the robot that carries the linear motor (0: rigid). With
        `robot_frequency` and `robot_damping_ratio` it is a lightly damped mode that moves the
        motor's stator, so the bar is not where the drive says.
    robot_frequency, robot_damping_ratio : float
        Natural frequency [Hz] and damping ratio of that mode.
    slider_mass : float
        Mass [kg] of the linear motor's slider; its inertia loads the robot.
    hinge_friction_torque : float
        Coulomb friction [N m] in the lower-arm hinge (model parameter ``T_f``).
    bellow_lag, bellow_delay : float
        First-order time constant [s] and transport delay [s] between the measured pressure
        (sensor at the valve) and the pressure in the bellow.
    bellow_angle_coefficient : float
        Angle dependence [1/rad] of the bellow torque (model parameter ``kappa_p``).
    unilateral_contact : bool
        The bar can only push the head: contact loss when the head falls behind.
    head_stiffening : float
        Cubic stiffness [N/m^3] of the head suspension (model parameter ``k_c3``).
    force_noise, force_offset : float
        Standard deviation and offset [N] of the force signal.
    pressure_noise, pressure_offset : float
        Standard deviation and offset [bar] of the pressure signal.
    laser_noise, laser_offset : float
        Standard deviation and offset [m] of the two laser distance sensors (cross bar).
    force_quantum, pressure_quantum, laser_quantum : float
        Quantisation steps of the converters (0: none).
    """

    bar_mass: float = 1.5
    robot_compliance: float = 1.0e-6
    robot_frequency: float = 12.0
    robot_damping_ratio: float = 0.03
    slider_mass: float = 3.0
    hinge_friction_torque: float = 20.0
    bellow_lag: float = 0.15
    bellow_delay: float = 0.03
    bellow_angle_coefficient: float = 0.3
    unilateral_contact: bool = True
    head_stiffening: float = 4.0e7
    force_noise: float = 0.5
    force_offset: float = 2.0
    pressure_noise: float = 0.005
    pressure_offset: float = 0.02
    laser_noise: float = 1.5e-3
    laser_offset: float = 5.0e-3
    force_quantum: float = 2000.0 / 2**16
    pressure_quantum: float = 10.0 / 2**16
    laser_quantum: float = 0.5 / 2**16

    def __post_init__(self) -> None:
        for item in fields(self):
            value = getattr(self, item.name)
            if item.name == "unilateral_contact":
                if not isinstance(value, bool):
                    raise ValueError(f"unilateral_contact = {value!r}: must be true or false")
                continue
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{item.name} = {value!r}: must be a finite number")
            signed = item.name in ("bellow_angle_coefficient", "head_stiffening", "force_offset",
                                   "pressure_offset", "laser_offset")
            if not signed and value < 0:
                raise ValueError(f"{item.name} = {value!r}: must be >= 0")
        if self.robot_compliance > 0 and self.robot_frequency <= 0:
            raise ValueError(f"robot_frequency = {self.robot_frequency!r}: must be > 0 Hz "
                             "when robot_compliance > 0")

    @classmethod
    def none(cls) -> "RigImperfections":
        """The ideal rig: every effect off, perfect sensors."""
        zero = {item.name: 0.0 for item in fields(cls) if item.name != "unilateral_contact"}
        zero["robot_frequency"] = cls.robot_frequency
        return cls(**zero, unilateral_contact=False)

    def with_only(self, *names: str) -> "RigImperfections":
        """A copy with only the named effects (at this instance's magnitudes), the rest off."""
        unknown = [n for n in names if n not in {f.name for f in fields(self)}]
        if unknown:
            raise ValueError(f"unknown imperfection(s) {unknown}; known: {[f.name for f in fields(self)]}")
        return replace(RigImperfections.none(), **{n: getattr(self, n) for n in names})

    def model_parameters(self) -> dict[str, float]:
        """The pantograph model parameters that carry the effects inside the FMU."""
        return {"T_f": self.hinge_friction_torque, "kappa_p": self.bellow_angle_coefficient,
                "k_c3": self.head_stiffening,
                "unilateral_contact": 1.0 if self.unilateral_contact else 0.0}

    def to_dict(self) -> dict[str, Any]:
        """Plain values plus their provenance, for a dataset's truth record."""
        return {**asdict(self), "provenance": dict(PROVENANCE)}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "RigImperfections":
        """Inverse of :meth:`to_dict` (extra keys such as ``provenance`` are ignored)."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in values.items() if k in known})
