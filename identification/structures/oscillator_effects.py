"""Two- and three-mass oscillators with a nonlinear force inside their dynamics (the diagnosis'
``coulomb_friction`` and ``cubic_stiffness`` candidates where the nominal is an oscillator).

A friction or a hardening spring acts on a mass and reaches every output through the dynamics:
a Coulomb friction at the frame's hinges slows the cross bar (``y_cb``) far more than it changes
the contact force, a stiffening suspension shifts a resonance. An additive term on one output
(what the diagnosis falls back to for a nominal without such a form) cannot express either, so
the refit could not close the gap and the effect went unnamed. :class:`NonlinearOscillator` is the
oscillator of :mod:`~panto.identification.structures.oscillators` with

- ``coulomb_friction``: ``-F_f,i tanh(v_i / v_eps)`` on every mass ``i`` (``F_f,i`` >= 0 [N]
  fitted, ``v_eps`` held at 1 mm/s: the oscillators' own friction model, eq. 2.35 smoothed);
- ``cubic_stiffness``: every chain spring ``i`` (base-1, 1-2, 2-3) pulls with its linear
  force (``k_i d_i``, with the static balance ``F_0``) plus ``k_i (kq_i e^2 + kc_i e^3)``,
  ``e = d_i - c_i``, where ``d_i`` is its deflection and ``c_i`` a fixed deflection, the
  spring law's centre (``centres``: the diagnosis gives the nominal's static deflection at the
  training run's first sample, its operating point, and keeps it for every other run);
  ``kc_i`` [1/m^2] is the relative
  symmetric stiffening (``> 0`` hardening, ``< 0`` softening), ``kq_i`` [1/m] the asymmetric
  one (stiffer when stretched than when compressed, or the other way). A run that starts
  elsewhere starts in the nonlinear static equilibrium (Newton from the linear one). The law is
  a property of the spring, not of the run: centred at each run's own first sample, the terms
  fitted on one run meant other terms on a run starting 15 mm away (seen held-out three-mass/
  cubic_stiffness/977: training at the plant's ceiling, validation 3.9 points worse than the
  linear model). Without ``centres`` each run is centred at its own first sample (a single
  run's view, for a structure used on its own). The quadratic term is
  there because a spring that stiffens about its own free length, ``k3 (d0 + e)^3`` with the
  static preload ``d0``, is ``3 k3 d0 e^2 + k3 e^3`` about the operating point beyond the linear
  part: with a preload several times the motion the quadratic term is the larger (3 d0 / e:
  4-10 times on the independent benchmark plants whose hardening went unnamed without it). The
  cubic polynomial about the operating point is the general third-order spring law, whatever its
  centre.

Which mass or spring carries the effect is not assumed: each gets its own parameter, all start at
zero (the linear nominal), and the refit lets the data decide (the diagnosis tests the largest
``|theta| / sigma`` among them: :attr:`NonlinearOscillator.magnitude_parameters`).

Simulation: Strang splitting per sub-step ``h`` (at most :data:`MAX_SUBSTEP` s): half a step of
the nonlinear forces (positions frozen: the spring kick ``v += h/2 F(z) / m`` is exact, the
friction flow in closed form, :func:`~panto.identification.structures.oscillators.coulomb_flow`),
the exact linear flow over ``h`` (first-order hold), the other half step: second order, and the
stiff friction never limits the step. Without the cubic springs the oscillators' own friction
integration is used (compiled: :mod:`~panto.identification.structures.friction_kernel`).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.structures import friction_kernel, oscillators
from panto.identification.structures.oscillator_mode import OscillatorWithMode
from panto.identification.structures.oscillators import (DEFAULT_OUTPUTS, OUTPUT_NAMES,
                                                         OscillatorStructure, coulomb_flow,
                                                         discretise)

#: Longest integration sub-step [s] of the nonlinear forces.
MAX_SUBSTEP = 2.5e-3
#: Smoothing velocity of the friction [m/s] (the oscillators' default).
FRICTION_VELOCITY = 1e-3
#: Bound of the relative cubic stiffening ``|kc_i|`` [1/m^2] (a 1 mm deflection doubles the
#: spring force at 1e6).
CUBIC_BOUND = 1e8
#: Bound of the relative quadratic stiffening ``|kq_i|`` [1/m] (a 1 mm deflection doubles the
#: spring force at 1e3).
QUADRATIC_BOUND = 1e5
#: Bound of a friction force [N].
FRICTION_BOUND = 500.0
#: The effects this module puts inside an oscillator.
OSCILLATOR_EFFECTS = ("coulomb_friction", "cubic_stiffness")
#: The prefixes of the spring terms' parameters (quadratic, cubic).
_SPRING_TERMS = ("kq", "kc")


class NonlinearOscillator(OscillatorStructure):
    """An oscillator with Coulomb friction on every mass and/or quadratic and cubic terms on
    every spring.

    Parameters
    ----------
    masses : {2, 3}
    friction, cubic : bool
        Which nonlinear forces the structure carries (module notes).
    outputs, hold
        As :class:`~panto.identification.structures.oscillators.OscillatorStructure`.
    v_eps : float
        Friction smoothing velocity [m/s], held (not fitted).
    centres : sequence of float, optional
        The spring law's centre ``c_i`` [m] per chain spring (module notes); default: each run's
        own static deflection at its first sample.
    """

    #: Its outputs only: the linear oscillator's exact accelerations (``A x + B u``) leave out
    #: the nonlinear forces.
    simulable_outputs = OUTPUT_NAMES

    def __init__(self, masses: int, *, friction: bool = False, cubic: bool = False,
                 outputs: Sequence[str] = DEFAULT_OUTPUTS, hold: str = "foh",
                 v_eps: float = FRICTION_VELOCITY,
                 centres: Sequence[float] | None = None) -> None:
        if not (friction or cubic):
            raise IdentificationError("nonlinear oscillator: give friction, cubic, or both")
        super().__init__(masses, friction, outputs=outputs, hold=hold, substeps=1)
        if not v_eps > 0:
            raise IdentificationError(f"nonlinear oscillator: v_eps = {v_eps} m/s must be > 0")
        self.cubic, self.v_eps = bool(cubic), float(v_eps)
        self.centres = None if centres is None else tuple(float(c) for c in centres)
        if self.centres is not None and (len(self.centres) != masses or not all(
                math.isfinite(c) for c in self.centres)):
            raise IdentificationError(f"nonlinear oscillator: centres {centres} must be "
                                      f"{masses} finite deflections [m]")
        words = {2: "two", 3: "three"}[masses]
        self.name = f"{words}-mass" + "".join(
            f"+{e}" for e, on in zip(OSCILLATOR_EFFECTS, (friction, cubic)) if on)
        if cubic:
            self.parameter_names = tuple(self.parameter_names) + tuple(
                f"{kind}{i + 1}" for kind in ("kq", "kc") for i in range(masses))

    @property
    def held_parameters(self) -> tuple[str, ...]:
        """Parameters of the structure that an augmentation does not fit (``v_eps``)."""
        return ("v_eps",) if self.friction else ()

    @property
    def balance_parameters(self) -> tuple[str, ...]:
        """Nominal parameters a refit frees together with the effect's own when it fits those
        first (the diagnosis' staged refit): a quadratic spring term has a non-zero mean, so
        its static force moves the operating point unless the static balance ``F_0`` moves with
        it (held, a preloaded hardening base spring was fitted to a quarter of its size with
        the quadratic taken up by a stiff upper spring: seen held-out three-mass/
        cubic_stiffness/1847)."""
        return ("F_0",) if self.cubic else ()

    @property
    def staged_groups(self) -> tuple[tuple[str, ...], ...]:
        """The effect parameters' groups a staged refit also tries one at a time (each spring's
        quadratic and cubic terms): which spring carries a hardening is not known, and all
        springs' terms from zero at once let the stiff upper spring, whose tiny deflection needs
        huge coefficients, take the first steps and hold them (seen held-out three-mass/
        cubic_stiffness/1847: the base spring's hardening ended on spring 2 at a quarter of the
        validation gain)."""
        if not self.cubic:
            return ()
        return tuple((f"kq{i + 1}", f"kc{i + 1}") for i in range(self.masses))

    @property
    def magnitude_parameters(self) -> tuple[str, ...]:
        """The effects' size parameters (zero: the effect absent)."""
        return tuple(n for n in self.parameter_names if n.startswith(("F_f", "kq", "kc")))

    def nominal(self) -> dict[str, float]:
        """The oscillator's nominal values; the nonlinear forces start at zero."""
        values = super().nominal()
        if self.friction:
            values.update({f"F_f{i + 1}": 0.0 for i in range(self.masses)}, v_eps=self.v_eps)
        if self.cubic:
            values.update({f"{kind}{i + 1}": 0.0 for kind in ("kq", "kc")
                           for i in range(self.masses)})
        return values

    def bounds(self) -> dict[str, tuple[float, float]]:
        """The oscillator's bounds; friction ``[0, 500]`` N, ``kq_i`` within ``+-1e5`` 1/m,
        ``kc_i`` within ``+-1e8`` 1/m^2."""
        values = super().bounds()
        if self.friction:
            values.update({f"F_f{i + 1}": (0.0, FRICTION_BOUND) for i in range(self.masses)})
        if self.cubic:
            values.update({f"kq{i + 1}": (-QUADRATIC_BOUND, QUADRATIC_BOUND)
                           for i in range(self.masses)})
            values.update({f"kc{i + 1}": (-CUBIC_BOUND, CUBIC_BOUND) for i in range(self.masses)})
        return values

    def units(self) -> dict[str, str]:
        """Units: the oscillator's, ``kq_i`` in 1/m, ``kc_i`` in 1/m^2."""
        base = {n: u for n, u in OscillatorStructure(self.masses, self.friction,
                                                     outputs=self.output_names).units().items()}
        return {n: base.get(n, "1/m" if n.startswith("kq") else "1/m^2")
                for n in self.parameter_names}

    def values(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """Nominal values overridden by `parameters` (checked by the oscillator)."""
        linear = {k: v for k, v in parameters.items() if not k.startswith(_SPRING_TERMS)}
        cubic = {k: float(v) for k, v in parameters.items() if k.startswith(_SPRING_TERMS)}
        unknown = sorted(set(cubic) - set(self.parameter_names))
        if unknown:
            raise IdentificationError(f"{self.name}: unknown parameters {unknown}")
        values = super().values(linear)
        values.update({k: v for k, v in self.nominal().items() if k.startswith(_SPRING_TERMS)})
        values.update(cubic)
        bad = {k: v for k, v in cubic.items() if not math.isfinite(v)}
        if bad:
            raise IdentificationError(f"{self.name}: invalid parameter values {bad}")
        return values

    def matrices(self, parameters: Mapping[str, float]) -> tuple[np.ndarray, ...]:
        """The linear part's ``(A, B, C, D)`` (the oscillator's)."""
        linear = {k: v for k, v in parameters.items() if not k.startswith(_SPRING_TERMS)}
        return super().matrices(linear)

    def _spring_terms(self, v: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray] | None:
        """``k_i kc_i`` [N/m^3] and ``k_i kq_i`` [N/m^2] per chain spring, None when every
        term is zero (the linear oscillator)."""
        n = self.masses
        if not self.cubic or all(v[f"{kind}{i + 1}"] == 0.0 for kind in _SPRING_TERMS
                                 for i in range(n)):
            return None
        return (np.array([v[f"k{i + 1}"] * v[f"kc{i + 1}"] for i in range(n)]),
                np.array([v[f"k{i + 1}"] * v[f"kq{i + 1}"] for i in range(n)]))

    def equilibrium(self, parameters: Mapping[str, float], eta: float, p: float) -> np.ndarray:
        """Static equilibrium ``[z; 0]`` for constant inputs: the linear one, or with spring
        terms about fixed :attr:`centres` the nonlinear one by Newton's method from there.

        Raises IdentificationError where Newton's method finds none (a softening spring past
        its turning point)."""
        x0 = super().equilibrium(parameters, eta, p)
        v = self.values(parameters)
        terms = self._spring_terms(v)
        if terms is None or self.centres is None:
            return x0
        springs, quadratic = terms
        n = self.masses
        a, b, _, _ = self.matrices(parameters)
        mass = np.array([v[f"m{i + 1}"] for i in range(n)])
        stiffness = a[n:, :n] * mass[:, None]  # forces [N] per displacement, and at rest:
        load = (b[n:] @ np.array([eta, p, 1.0])) * mass
        centres = np.array(self.centres)
        z = x0[:n].copy()
        for _ in range(50):
            e = np.diff(z, prepend=0.0) - centres
            tension = (quadratic + springs * e) * e * e
            slope = (2.0 * quadratic + 3.0 * springs * e) * e
            force = stiffness @ z + load - tension
            force[:-1] += tension[1:]
            # d(force)/dz: each spring's slope pulls both its masses, as a chain of springs
            chain = -self._chain(slope)
            try:
                step = np.linalg.solve(stiffness + chain, -force)
            except np.linalg.LinAlgError:
                break
            z += step
            if np.max(np.abs(step)) <= 1e-13 * (1.0 + np.max(np.abs(z))):
                # a rest, not a saddle: the stiffness there must still hold the masses (a
                # softening spring past its turning point has a root that is not stable)
                symmetric = 0.5 * (stiffness + chain + (stiffness + chain).T)
                if np.all(np.linalg.eigvalsh(symmetric) < 0.0):
                    return np.concatenate([z, np.zeros(n)])
                break
        raise IdentificationError(f"{self.name}: no static equilibrium with the spring terms at "
                                  f"eta = {eta:.4g} m, p = {p:.4g} bar")

    def linear_system(self, parameters: Mapping[str, float], data: IdentificationData):
        """Not linear: raises NotImplementedError."""
        raise NotImplementedError(f"{self.name}: a nonlinear force is not linear")

    def with_effect(self, effect: str, setting: Mapping[str, Any]) -> "NonlinearOscillator":
        """This structure with one more nonlinear force (:data:`OSCILLATOR_EFFECTS`)."""
        return oscillator_with_effect(self, effect, setting)

    def simulate_inputs(self, parameters: Mapping[str, float], u: np.ndarray,
                        period: float) -> np.ndarray:
        """Free run for input samples ``u`` (columns eta, p, 1) every `period` seconds."""
        v = self.values(parameters)
        a, b, c, d = self.matrices(parameters)
        x0 = self.equilibrium(parameters, u[0, 0], u[0, 1])
        substeps = max(1, math.ceil(period / MAX_SUBSTEP - 1e-9))
        n = self.masses
        mass = np.array([v[f"m{i + 1}"] for i in range(n)])
        friction = np.array([v[f"F_f{i + 1}"] for i in range(n)]) / mass if self.friction \
            else np.zeros(n)
        terms = self._spring_terms(v)
        if terms is not None:
            states = _simulate_nonlinear(a, b, u, x0, period, substeps, self.hold, friction,
                                         self.v_eps, terms[0], mass, quadratic=terms[1],
                                         centre=self.centres)
        elif self.friction:
            states = oscillators._simulate_friction(a, b, u, x0, period, substeps, self.hold,
                                                    friction, self.v_eps)
        else:
            phi, gamma0, gamma1 = discretise(a, b, period, self.hold)
            drive = u[:-1] @ gamma0.T + np.diff(u, axis=0) @ gamma1.T
            states = oscillators.propagate(phi, drive, x0)
        rows = [OUTPUT_NAMES.index(o) for o in self.output_names]
        y = states @ c[rows].T + u @ d[rows].T
        if not np.all(np.isfinite(y)):
            raise IdentificationError(f"{self.name}: simulation diverged for {dict(v)}")
        return y


def oscillator_with_effect(structure: OscillatorStructure, effect: str,
                           setting: Mapping[str, Any]
                           ) -> NonlinearOscillator | OscillatorWithMode:
    """`structure` (a linear, friction or nonlinear oscillator) with `effect` inside its dynamics
    (``extra_mode``: a linear one only, :func:`_with_mode`).

    Raises IdentificationError for an effect without an inside form here (the diagnosis then
    adds it from outside).
    """
    if effect == "extra_mode":
        return _with_mode(structure, setting)
    if effect not in OSCILLATOR_EFFECTS:
        raise IdentificationError(f"{structure.name}: no inside form for effect {effect!r}")
    friction = bool(structure.friction) or effect == "coulomb_friction"
    cubic = bool(getattr(structure, "cubic", False)) or effect == "cubic_stiffness"
    centres = getattr(structure, "centres", None)
    if centres is None and effect == "cubic_stiffness":
        centres = setting.get("centres")
    return NonlinearOscillator(structure.masses, friction=friction, cubic=cubic,
                               outputs=structure.output_names, hold=structure.hold,
                               v_eps=float(getattr(structure, "v_eps", FRICTION_VELOCITY)),
                               centres=centres)


def _with_mode(structure: OscillatorStructure, setting: Mapping[str, Any]) -> OscillatorWithMode:
    """A linear oscillator with an extra mass on mass ``setting["attached"]`` (default the head),
    its start frequency and damping the setting's (``frequency_hz``, ``damping``); raises
    IdentificationError for an oscillator with friction or nonlinear springs."""
    if type(structure) is not OscillatorStructure or structure.friction:
        raise IdentificationError(f"{structure.name}: an extra mass inside goes only on a linear "
                                  "oscillator")
    return OscillatorWithMode(structure.masses, attached=setting.get("attached"),
                              frequency=float(setting.get("frequency_hz", 10.0)),
                              damping=float(setting.get("damping", 0.05)),
                              highest=0.95 * float(setting["nyquist"]) if "nyquist" in setting
                              else 1e3,
                              outputs=structure.output_names, hold=structure.hold)


def _deflections(z: np.ndarray) -> np.ndarray:
    """Deflections of the chain springs base-1, 1-2, ... for the mass displacements `z`."""
    return np.diff(z, prepend=0.0)


def _simulate_nonlinear(a: np.ndarray, b: np.ndarray, u: np.ndarray, x0: np.ndarray,
                        period: float, substeps: int, hold: str, friction: np.ndarray,
                        v_eps: float, springs: np.ndarray, mass: np.ndarray,
                        compiled: bool | None = None,
                        quadratic: np.ndarray | None = None,
                        centre: Sequence[float] | None = None) -> np.ndarray:
    """States at the samples: Strang splitting of the nonlinear forces and the linear flow, in C
    (:func:`~panto.identification.structures.friction_kernel.nonlinear_run`) when the kernel is
    available (or `compiled` True), else this loop (the reference). `springs` ``k_i kc_i``
    [N/m^3] and `quadratic` ``k_i kq_i`` [N/m^2] (default none) per chain spring, about the
    deflections `centre` [m] (default: those of `x0`)."""
    n = len(x0) // 2
    quadratic = np.zeros(n) if quadratic is None else np.asarray(quadratic, dtype=float)
    h = period / substeps
    phi, gamma0, gamma1 = discretise(a, b, h, hold)
    du = np.diff(u, axis=0) if hold == "foh" else np.zeros_like(u[:-1])
    fractions = np.arange(substeps) / substeps
    starts = u[:-1, None, :] + fractions[None, :, None] * du[:, None, :]
    drive = (starts @ gamma0.T + (du[:, None, :] / substeps) @ gamma1.T).reshape(-1, 2 * n)
    centre = _deflections(x0[:n]) if centre is None else np.asarray(centre, dtype=float)
    decay = friction * (h / 2.0) / v_eps
    rubbing = bool(np.any(decay > 0.0))
    kick = (h / 2.0) / mass
    states = np.empty((len(u), 2 * n))
    states[0] = x0
    x = x0.copy()
    if compiled is None:
        compiled = friction_kernel.available()
    if compiled:
        try:
            friction_kernel.nonlinear_run(phi, drive, x, substeps, decay, v_eps, springs,
                                          quadratic, centre, kick, states)
        except ArithmeticError as error:
            raise IdentificationError(str(error)) from error
        return states
    z, v = x[:n], x[n:]  # views: updated in place
    phi_zz, phi_zv, phi_vz, phi_vv = phi[:n, :n], phi[:n, n:], phi[n:, :n], phi[n:, n:]
    tension = np.empty(n)
    stretch = np.empty(n)
    force = np.empty(n)

    def spring_kick() -> None:  # tension (quadratic + springs e) e e, e from the operating point
        np.subtract(z, centre, out=stretch)
        stretch[1:] -= z[:-1]
        np.multiply(springs, stretch, out=tension)
        np.add(tension, quadratic, out=tension)
        np.multiply(tension, stretch, out=tension)
        np.multiply(tension, stretch, out=tension)
        np.negative(tension, out=force)
        force[:-1] += tension[1:]
        np.multiply(force, kick, out=force)
        np.add(v, force, out=v)

    with np.errstate(over="ignore", invalid="ignore"):
        for step in range(len(drive)):
            spring_kick()
            if rubbing:
                v[:] = coulomb_flow(v, decay, v_eps)
            d = drive[step]
            new_z = phi_zz @ z + phi_zv @ v + d[:n]
            v[:] = phi_vz @ z + phi_vv @ v + d[n:]
            z[:] = new_z
            if rubbing:
                v[:] = coulomb_flow(v, decay, v_eps)
            spring_kick()
            if (step + 1) % substeps == 0:
                states[(step + 1) // substeps] = x
    if not np.all(np.isfinite(states)):
        raise IdentificationError("nonlinear oscillator: the simulation diverged")
    return states


__all__ = ["NonlinearOscillator", "oscillator_with_effect", "OSCILLATOR_EFFECTS", "MAX_SUBSTEP"]
