"""A rigid-body inverse-dynamics structure for position-controlled axes (EMPS-like systems).

The force (or motor torque) that moves a rigid body of mass ``M`` with viscous friction ``F_v``
and a constant offset ``F_0`` (gravity, sensor offset) is

.. math::

    F(t) = M \\ddot q(t) + F_v \\dot q(t) + F_0 \\; [+ F_c \\tanh(\\dot q / v_s)],

with ``q`` the *measured* position input, differentiated by a zero-phase filter (4th-order
Butterworth forward and backward, then centred differences), as in the inverse dynamic
identification model of Gautier and Janot (the EMPS benchmark, Janot, Gautier & Brunot 2019).
It is an equation-error structure: the "simulation" is the force computed from the measured
motion, so it is linear in the parameters and least squares solves it in one step. The Coulomb
term is the diagnosis' ``coulomb_friction`` augmentation (:meth:`RigidBody.with_effect`).

Listed in :mod:`panto.identification.structures.registry` as ``rigid-body`` (not in the
comparison).
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import signal as sps

from panto.identification.estimation.base import (IdentificationData, IdentificationError, IdentificationResult,
                                 ModelStructure)

#: Effects the rigid body takes inside its force equation.
RIGID_BODY_EFFECTS = ("coulomb_friction",)


@lru_cache(maxsize=16)
def _motion(key: bytes, n: int, sample_period: float, cutoff: float | None
            ) -> tuple[np.ndarray, np.ndarray]:
    position = np.frombuffer(key, float, n)
    smooth = position
    if cutoff is not None and cutoff < 1.0 and n > 27:
        smooth = sps.sosfiltfilt(sps.butter(4, cutoff, output="sos"), position)
    velocity = np.gradient(smooth, sample_period)
    return velocity, np.gradient(velocity, sample_period)


def motion(position: np.ndarray, sample_period: float, cutoff: float | None
           ) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration of a measured position (zero-phase Butterworth at `cutoff`
    times the Nyquist frequency, None: no filter, then centred differences); cached per signal."""
    x = np.ascontiguousarray(position, float)
    return _motion(x.tobytes(), len(x), float(sample_period),
                   None if cutoff is None else float(cutoff))


class RigidBody(ModelStructure):
    """``F = M q'' + F_v q' + F_0 [+ F_c tanh(q' / v_s)]`` from a measured position (module notes).

    Parameters
    ----------
    position : str
        Input holding the measured position [m] (or angle).
    force : str
        Output holding the force [N] (or torque, or a control effort proportional to it).
    cutoff : float or None
        Differentiation low-pass, fraction of the Nyquist frequency (None: the position is
        already smooth, e.g. filtered before decimation; only centred differences).
    initial : mapping, optional
        Nominal parameter values.
    friction_width : float or None
        ``v_s`` of the Coulomb term [m/s] (0: ``sign``); None: no Coulomb term.
    """

    #: Effects the nominal already holds (its ``M q''`` is the inertia a sensor mass would add).
    covered_effects = ("sensor_inertia",)

    def __init__(self, position: str = "q", force: str = "force", *, cutoff: float | None = None,
                 initial: Mapping[str, float] | None = None,
                 friction_width: float | None = None) -> None:
        self.name = "rigid-body"
        self.input_names, self.output_names = (position,), (force,)
        self.cutoff, self.friction_width = cutoff, friction_width
        names = ["M", "F_v", "F_0"] + (["F_c"] if friction_width is not None else [])
        self.parameter_names = tuple(names)
        self._nominal = {"M": 1.0, "F_v": 1.0, "F_0": 0.0, "F_c": 0.0}
        self._nominal.update({k: float(v) for k, v in (initial or {}).items()})
        self._nominal = {n: self._nominal[n] for n in names}

    def with_effect(self, effect: str, setting: Mapping[str, Any]) -> "RigidBody":
        """The structure with a Coulomb term (``setting["v_s"]``, start ``setting["start"]``)."""
        if effect not in RIGID_BODY_EFFECTS:
            raise IdentificationError(f"rigid-body: no inside form for effect {effect!r}")
        return RigidBody(self.input_names[0], self.output_names[0], cutoff=self.cutoff,
                         initial={**self._nominal, "F_c": float(setting.get("start", 0.0))},
                         friction_width=float(setting.get("v_s", 0.0)))

    def with_nominal(self, values: Mapping[str, float]) -> "RigidBody":
        """The same structure with other nominal values."""
        return RigidBody(self.input_names[0], self.output_names[0], cutoff=self.cutoff,
                         initial={**self._nominal, **values}, friction_width=self.friction_width)

    def nominal(self) -> dict[str, float]:
        return dict(self._nominal)

    def bounds(self) -> dict[str, tuple[float, float]]:
        """Symmetric, wide: the data decide (``M`` and ``F_v`` may come out negative when a
        gain sign is flipped; that shows in the report)."""
        return {n: (-max(1e6, 1e4 * abs(v)), max(1e6, 1e4 * abs(v)))
                for n, v in self._nominal.items()}

    def regressors(self, data: IdentificationData) -> np.ndarray:
        """Columns ``[q'', q', 1 (, tanh(q'/v_s))]`` in :attr:`parameter_names` order."""
        velocity, acceleration = motion(data.input(self.input_names[0]), data.sample_period,
                                        self.cutoff)
        columns = [acceleration, velocity, np.ones(len(velocity))]
        if self.friction_width is not None:
            columns.append(np.tanh(velocity / self.friction_width) if self.friction_width > 0
                           else np.sign(velocity))
        return np.column_stack(columns)

    def simulate(self, parameters: Mapping[str, float], data: IdentificationData) -> np.ndarray:
        values = {**self._nominal, **{k: float(v) for k, v in parameters.items()}}
        theta = np.array([values[n] for n in self.parameter_names])
        return (self.regressors(data) @ theta)[:, None]


def rigid_body_from_data(data: IdentificationData, *, position: str | None = None,
                         force: str | None = None, cutoff: float | None = None) -> RigidBody:
    """A :class:`RigidBody` with least-squares start values from `data` (its first input and
    output unless named)."""
    structure = RigidBody(position or data.input_names[0], force or data.output_names[0],
                          cutoff=cutoff)
    phi = structure.regressors(data)
    y = data.output(structure.output_names[0])
    ok = np.isfinite(y)
    if ok.sum() <= phi.shape[1]:
        raise IdentificationError(f"{data.source or 'data'}: too few valid force samples")
    theta, *_ = np.linalg.lstsq(phi[ok], y[ok], rcond=None)
    return structure.with_nominal(dict(zip(structure.parameter_names, theta.tolist())))


def identify_rigid_body(data: IdentificationData, *, executor=None, progress=None,
                        cutoff: float | None = None, **options: Any) -> IdentificationResult:
    """Least-squares start, then :func:`~panto.identification.estimation.least_squares.fit_least_squares`
    (one step: the structure is linear in its parameters)."""
    from panto.identification.estimation.least_squares import fit_least_squares

    structure = rigid_body_from_data(data, cutoff=cutoff)
    for key in ("fixed", "method", "outputs"):
        options.pop(key, None)
    free: Sequence[str] = options.pop("free", None) or structure.parameter_names
    return fit_least_squares(structure, data.select_outputs(structure.output_names), free=free,
                             executor=executor, progress=progress, **options)


__all__ = ["RigidBody", "rigid_body_from_data", "identify_rigid_body", "motion",
           "RIGID_BODY_EFFECTS"]
