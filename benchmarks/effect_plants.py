"""Oscillator plants with one hidden effect each, written apart from the diagnosis under test
(issue 24, "Benchmark families the diagnosis was not written against").

Run by hand through ``benchmarks/diagnosis_families.py``; the physics is checked by
``tests/test_effect_plants.py``. Nothing here imports the identification package: the plants
are numpy and a Runge-Kutta loop only, on the truth draws and signal helpers of
``benchmarks/plants.py``.

The plant
    The two- or three-mass oscillator of ``plants.py`` (masses numbered from the bottom, heights
    ``x_i`` [m], springs relaxed at ``y_0``, bellow force ``p_gain p + F_0`` on mass 1, carbon
    contact ``k_E`` between the head and the wire height ``eta``), Newton's law per mass written
    force by force (:meth:`EffectPlant.forces`), plus at most one hidden effect of strength
    ``s`` in [0, 1] (mapped log-uniformly onto the physical range of :data:`RANGES`):

    ============================  ======================================================  ===========
    label                         mechanism                                               parameter
    ============================  ======================================================  ===========
    ``coulomb_friction``          ``-F_f tanh(v_1 / v_eps)`` on mass 1 (v_eps = 1 mm/s)   F_f [N]
    ``cubic_stiffness``           ``-k3 (x_1 - y_0)^3`` beside the base spring            k3 [N/m^3]
    ``dead_zone``                 the actuator moves ``eta`` only beyond +-w of 2 m       w [m]
    ``input_delay``               the real ``eta`` (or ``p``) is the command delayed      tau [s]
    ``actuator_lag``              ``T eta_r' = eta - eta_r`` (motor) or bellow ``p``      T [s]
    ``sensor_inertia``            measured force ``F_c + m_s xi''`` (sensor mass)         m_s [kg]
    ``extra_mode``                mass ``mu m_j`` on the head (or frame), f_e, zeta 0.03  mu [-]
    ``contact_loss``              ``F_c = max(0, k_E (x_n - eta))``, preload scaled       g [-]
    ``offset``                    force offset ``+-d/2``, sign flipped between the runs   d [N]
    ``saturation``                force sensor clips at its range ``F_sat``               share [-]
    ``hysteresis``                Bouc-Wen element in the base spring (delta = 4 mm)      F_h [N]
    ``sign_blind_sensor``         laser (or force) reads ``r + |y - r|``                  share [-]
    ``creep``                     Maxwell element beside spring 2, tau_m 1-5 s            k_m/k_2
    ``time_varying_gain``         force sensor gain ``1 + g sin(2 pi t / P + phi_run)``   g [-]
    ============================  ======================================================  ===========

    The last four are outside the diagnosis' vocabulary (the right verdict is ``unexplained``);
    ``clean`` has no effect (the right verdict is ``none``). ``saturation`` and
    ``sign_blind_sensor`` set their level from the training run's noise-free signal (the share of
    samples clipped or folded), then keep it for the validation run: one plant, two runs.
    ``contact_loss`` scales the static contact force (``F_0`` lowered or raised) by
    ``g`` = 3 ... 0.1 so that the weakest runs barely lift off and the strongest fly.

Runs
    The run starts at rest in the static equilibrium of the first input sample (found by
    :func:`scipy.optimize.fsolve` from the linear one); inputs are linear between samples (as the
    structures assume); classic fourth-order Runge-Kutta with a fixed number of sub-steps per
    sample (at most 0.5 ms, less for a stiff friction or a fast lag) integrates the record, so no
    input kink falls inside a sub-step (an adaptive solver spent ~35 steps per sample on them).

Cases (:func:`draw_spec`, :func:`effect_case`)
    Per seed: one or two inputs (one: ``p`` held at 4.5 bar, still recorded), one to three outputs
    (``F_c``; ``+ y_cb``; ``+ xi``), excitation APRBS, multisine, chirp or ramps, 50-500 Hz,
    20-120 s (at most :data:`MAX_SAMPLES` samples), SNR 20-40 dB (``plants.add_noise``). A training
    and a validation run: the same plant, different input realisations and noise. Detectability
    (from the truth): per output, the fit [%] of the noise-free plant with the effect on the noisy
    validation data less that of the same plant without it (same parameters).
"""
from __future__ import annotations

import math
import sys
import zlib
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy.optimize import fsolve

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plants  # noqa: E402  (the sibling benchmark module: truth draws and signal helpers)

#: Effects of the diagnosis' vocabulary (names as its ``EFFECTS``).
LIBRARY = ("coulomb_friction", "cubic_stiffness", "dead_zone", "input_delay", "actuator_lag",
           "sensor_inertia", "extra_mode", "contact_loss", "offset", "saturation")
#: Mechanisms outside that vocabulary.
OUT_OF_LIBRARY = ("hysteresis", "sign_blind_sensor", "creep", "time_varying_gain")
#: Every label, ``clean`` first.
LABELS = ("clean",) + LIBRARY + OUT_OF_LIBRARY
#: Physical range (strength 0 -> 1, log-uniform) of each effect's parameter (module table).
RANGES = {"coulomb_friction": (0.3, 30.0), "cubic_stiffness": (1e3, 1e6),
          "dead_zone": (5e-6, 2e-3), "input_delay": (2e-4, 5e-2), "actuator_lag": (5e-4, 5e-2),
          "sensor_inertia": (0.05, 5.0), "extra_mode": (5e-4, 0.2), "contact_loss": (3.0, 0.1),
          "offset": (0.05, 30.0), "saturation": (1e-3, 0.25), "hysteresis": (0.5, 60.0),
          "sign_blind_sensor": (5e-3, 0.4), "creep": (0.01, 0.6), "time_varying_gain": (5e-3, 0.3)}
#: Bellow lag range [s] (``actuator_lag`` on ``p``): the bellow is slower than the motor.
BELLOW_LAG = (0.05, 2.0)
EXCITATIONS = ("aprbs", "multisine", "chirp", "ramps")
RATES = (50.0, 100.0, 200.0, 500.0)
#: Longest record [samples]: keeps a diagnosis of the longest runs within minutes.
MAX_SAMPLES = 24000
FRICTION_VELOCITY = 1e-3
#: Largest Runge-Kutta sub-step [s] of the plants.
DEFAULT_STEP = 5e-4
HYSTERESIS_WIDTH = 4e-3
OUTPUT_SETS = (("F_c",), ("F_c", "y_cb"), ("F_c", "y_cb", "xi"))


@dataclass(frozen=True)
class EffectPlant:
    """An oscillator plant with one hidden effect (module notes).

    Parameters
    ----------
    truth : mapping
        ``plants.draw_oscillator_truth`` keys (``m_i`` [kg], ``k_i`` [N/m], ``c_i`` [N s/m],
        ``k_E``, ``p_gain`` [N/bar], ``F_0`` [N], ``y_0`` [m], ``y_cb_offset`` [m]).
    effect : str
        A label of :data:`LABELS`.
    setting : mapping
        The effect's physical parameters (SI; keys as :func:`effect_setting` writes them).
    """

    truth: Mapping[str, float]
    effect: str = "clean"
    setting: Mapping[str, Any] = field(default_factory=dict)

    @cached_property
    def masses(self) -> int:
        """Number of masses (2 or 3)."""
        return sum(1 for k in self.truth if k[0] == "m" and k[1:].isdigit())

    @cached_property
    def _chain(self) -> tuple[list[float], list[float], list[float]]:
        """Masses, springs and dampers bottom to top, as floats (the force loop's constants)."""
        return tuple([float(self.truth[f"{kind}{i + 1}"]) for i in range(self.masses)]
                     for kind in "mkc")

    def extra_states(self) -> int:
        """States beyond heights and velocities: lag 1, extra mode 2, hysteresis 1, creep 1."""
        return {"actuator_lag": 1, "extra_mode": 2, "hysteresis": 1, "creep": 1}.get(self.effect, 0)

    def actuated(self, t: float, state: list[float], signals: "_Signals") -> tuple[float, float]:
        """The real wire height ``eta`` [m] and bellow pressure ``p`` [bar] at time `t` [s]."""
        eta, p = signals.at(t)
        s, e = self.setting, self.effect
        if e == "input_delay":
            delayed = signals.at(t - s["tau"])
            eta, p = (delayed[0], p) if s["target"] == "eta" else (eta, delayed[1])
        elif e == "dead_zone":
            offset = eta - s["centre"]
            eta = s["centre"] + math.copysign(max(abs(offset) - s["w"], 0.0), offset)
        elif e == "actuator_lag":
            eta, p = (state[-1], p) if s["target"] == "eta" else (eta, state[-1])
        return eta, p

    def forces(self, state: list[float], eta: float, p: float) -> tuple[list[float], dict]:
        """Net force [N] on every mass and the internal forces (``contact``, ``friction``)."""
        t, s, n, e = self.truth, self.setting, self.masses, self.effect
        _, k, c = self._chain
        x, v = state[:n], state[n:2 * n]
        deflection = x[0] - t["y_0"]
        force = [-k[0] * deflection - c[0] * v[0] + t["p_gain"] * p + t["F_0"]] + [0.0] * (n - 1)
        friction = 0.0
        if e == "coulomb_friction":
            friction = -s["F_f"] * math.tanh(v[0] / FRICTION_VELOCITY)
        elif e == "cubic_stiffness":
            force[0] -= s["k3"] * deflection ** 3
        elif e == "hysteresis":
            force[0] -= s["F_h"] / HYSTERESIS_WIDTH * state[2 * n]
        force[0] += friction
        for i in range(1, n):
            link = k[i] * (x[i] - x[i - 1]) + c[i] * (v[i] - v[i - 1])
            force[i] -= link
            force[i - 1] += link
        if e == "creep":
            relaxing = s["k_m"] * (x[1] - x[0] - state[2 * n])
            force[1] -= relaxing
            force[0] += relaxing
        elif e == "extra_mode":
            j = s["mass"]
            force[j] += s["k_e"] * (state[2 * n] - x[j]) + s["c_e"] * (state[2 * n + 1] - v[j])
        contact = t["k_E"] * (x[-1] - eta)
        if e == "contact_loss":
            contact = max(contact, 0.0)
        force[-1] -= contact
        return force, {"contact": contact, "friction": friction}

    def derivative(self, t: float, state: np.ndarray, signals: "_Signals") -> np.ndarray:
        """Time derivative of the state ``[x, v, extra]`` (module notes)."""
        return np.array(self._rates(t, state.tolist(), signals))

    def _rates(self, t: float, z: list[float], signals: "_Signals") -> list[float]:
        """:meth:`derivative` on plain lists (the Runge-Kutta loop's own form)."""
        n, s, e = self.masses, self.setting, self.effect
        force, _ = self.forces(z, *self.actuated(t, z, signals))
        mass = self._chain[0]
        rate = z[n:2 * n] + [f / m for f, m in zip(force, mass)]
        v1 = z[n]
        if e == "actuator_lag":
            command = signals.at(t)[0 if s["target"] == "eta" else 1]
            rate.append((command - z[-1]) / s["T"])
        elif e == "hysteresis":
            beta = gamma = 0.5 / HYSTERESIS_WIDTH
            rate.append(v1 - beta * abs(v1) * z[-1] - gamma * v1 * abs(z[-1]))
        elif e == "creep":
            rate.append((z[1] - z[0] - z[-1]) / s["tau_m"])
        elif e == "extra_mode":
            j = s["mass"]
            pull = s["k_e"] * (z[2 * n] - z[j]) + s["c_e"] * (z[2 * n + 1] - z[n + j])
            rate += [z[2 * n + 1], -pull / s["m_e"]]
        return rate

    def rest(self, eta: float, p: float) -> np.ndarray:
        """The state at rest for constant inputs (static force balance solved for the heights)."""
        n = self.masses
        linear = plants._equilibrium(self.truth, n, eta, p)

        def full(x: np.ndarray) -> list[float]:
            extra = {"actuator_lag": [eta if self.setting.get("target") == "eta" else p],
                     "extra_mode": [x[self.setting.get("mass", 0)], 0.0], "hysteresis": [0.0],
                     "creep": [x[1] - x[0]]}.get(self.effect, [])
            return list(x) + [0.0] * n + extra

        def residual(x: np.ndarray) -> np.ndarray:
            signals = _Signals(np.array([0.0, 1.0]), np.full(2, eta), np.full(2, p))
            real = self.actuated(0.0, full(x), signals)
            return np.array(self.forces(full(x), *real)[0]) / self.truth["k_E"]

        solution, _, status, message = fsolve(residual, linear, xtol=1e-13, full_output=True)
        if status != 1 and np.max(np.abs(residual(solution))) > 1e-9:
            raise RuntimeError(f"effect plant: no static equilibrium ({message})")
        return np.array(full(solution))

    def step_limit(self) -> float:
        """Largest RK4 step [s]: 0.5 ms, less for a stiff friction (lambda = F_f / (m_1 v_eps))
        or a fast lag, so that the step stays well inside RK4's stability region."""
        s, limit = self.setting, DEFAULT_STEP
        if self.effect == "coulomb_friction":
            limit = min(limit, 1.0 / (s["F_f"] / (self._chain[0][0] * FRICTION_VELOCITY)))
        elif self.effect == "actuator_lag":
            limit = min(limit, s["T"] / 2.0)
        return limit

    def simulate(self, time: np.ndarray, eta: np.ndarray, pressure: np.ndarray, *,
                 step: float | None = None) -> dict[str, np.ndarray]:
        """States and internal signals of one run (no sensor effects; :meth:`measure` adds them).

        Classic fourth-order Runge-Kutta with a fixed number of sub-steps per sample (at most
        `step` [s], default :meth:`step_limit`), so that no input kink lies inside a sub-step.

        Returns
        -------
        dict
            ``state`` (shape (states, samples)), ``x_i`` heights [m], ``F_c`` the real contact
            force [N], ``friction`` [N], ``acceleration`` of the head [m/s^2], ``eta``, ``p``
            (the real, actuated inputs).
        """
        signals = _Signals(time, eta, pressure)
        period = float(time[1] - time[0])
        substeps = max(1, math.ceil(period / (step or self.step_limit()) - 1e-9))
        h = period / substeps
        states = np.empty((2 * self.masses + self.extra_states(), len(time)))
        states[:, 0] = y = self.rest(float(eta[0]), float(pressure[0]))
        y = y.tolist()
        f, half, sixth = self._rates, h / 2, h / 6
        # on lists of floats: each element the same operations in the same order as the array
        # form ``y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)``, at a third less time
        for sample in range(1, len(time)):
            t = float(time[sample - 1])
            for i in range(substeps):
                ti = t + i * h
                k1 = f(ti, y, signals)
                k2 = f(ti + half, [a + half * b for a, b in zip(y, k1)], signals)
                k3 = f(ti + half, [a + half * b for a, b in zip(y, k2)], signals)
                k4 = f(ti + h, [a + h * b for a, b in zip(y, k3)], signals)
                y = [a + sixth * (p + 2 * q + 2 * r + w)
                     for a, p, q, r, w in zip(y, k1, k2, k3, k4)]
            states[:, sample] = y
        return self._record(time, states, signals)

    def _record(self, time: np.ndarray, states: np.ndarray, signals: "_Signals") -> dict:
        n = self.masses
        record = {name: np.empty(len(time)) for name in ("F_c", "friction", "acceleration",
                                                         "eta", "p")}
        for k, tk in enumerate(time):
            z = states[:, k].tolist()
            real = self.actuated(float(tk), z, signals)
            force, internal = self.forces(z, *real)
            record["F_c"][k], record["friction"][k] = internal["contact"], internal["friction"]
            record["acceleration"][k] = force[-1] / self._chain[0][-1]
            record["eta"][k], record["p"][k] = real
        record.update({f"x{i + 1}": states[i] for i in range(n)}, state=states)
        return record

    def measure(self, run: Mapping[str, np.ndarray], time: np.ndarray, index: int,
                outputs: tuple[str, ...]) -> dict[str, np.ndarray]:
        """The sensors' noise-free readings of `run` (`index` 0 training, 1 validation)."""
        n, s, e = self.masses, self.setting, self.effect
        measured = {"F_c": run["F_c"].copy(), "y_cb": run[f"x{n - 1}"] + self.truth["y_cb_offset"],
                    "xi": run[f"x{n}"].copy()}
        if e == "sensor_inertia":
            measured["F_c"] += s["m_s"] * run["acceleration"]
        elif e == "offset":
            measured["F_c"] += s["d"] / 2.0 * (1.0 if index == 0 else -1.0) * s["sign"]
        elif e == "saturation" and "F_sat" in s:
            measured["F_c"] = np.minimum(measured["F_c"], s["F_sat"])
        elif e == "sign_blind_sensor" and "reference" in s:
            y = measured[s["target"]]
            measured[s["target"]] = s["reference"] + np.abs(y - s["reference"])
        elif e == "time_varying_gain":
            phase = s["phases"][index]
            measured["F_c"] *= 1.0 + s["g"] * np.sin(2.0 * math.pi * time / s["period"] + phase)
        return {name: measured[name] for name in outputs}


@dataclass(frozen=True)
class _Signals:
    """Sampled command inputs on a uniform grid, linear between samples, held before the first
    sample and after the last."""

    time: np.ndarray
    eta: np.ndarray
    p: np.ndarray

    def __post_init__(self) -> None:
        grid = (float(self.time[0]), float(self.time[1] - self.time[0]), len(self.time) - 1)
        object.__setattr__(self, "_lists", (self.eta.tolist(), self.p.tolist(), grid))

    def at(self, t: float) -> tuple[float, float]:
        """``eta`` [m] and ``p`` [bar] at time `t` [s]."""
        eta, p, (t0, period, last) = self._lists
        u = min(max((t - t0) / period, 0.0), last)
        k = min(int(u), last - 1)
        w = u - k
        return eta[k] + w * (eta[k + 1] - eta[k]), p[k] + w * (p[k + 1] - p[k])


# --- cases ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CaseSpec:
    """What one benchmark case is: plant family, hidden effect and experiment (module notes)."""

    family: str
    label: str
    seed: int
    strength: float
    inputs: int
    outputs: tuple[str, ...]
    excitation: str
    rate: float
    duration: float
    snr_db: float

    @property
    def name(self) -> str:
        """``family/label/seed``."""
        return f"{self.family}/{self.label}/{self.seed}"


def stable_hash(text: str) -> int:
    """A hash that is the same in every process and Python version (CRC-32 of UTF-8)."""
    return zlib.crc32(text.encode("utf-8"))


def draw_spec(family: str, label: str, seed: int, *, quick: bool = False) -> CaseSpec:
    """The experiment of one case, drawn from its seed (module notes; `quick`: 20 s, <= 100 Hz)."""
    rng = np.random.default_rng([stable_hash(f"{family}/{label}"), seed])
    rate = float(rng.choice(RATES[:2] if quick else RATES))
    longest = min(120.0, MAX_SAMPLES / rate)
    duration = 20.0 if quick else float(round(rng.uniform(20.0, longest)))
    inputs = 1 if rng.uniform() < 0.3 else 2
    return CaseSpec(family, label, seed, float(rng.uniform()), inputs,
                    OUTPUT_SETS[int(rng.integers(3))], str(rng.choice(EXCITATIONS)), rate,
                    duration, float(rng.uniform(20.0, 40.0)))


def _scaled(label: str, strength: float, span: tuple[float, float] | None = None) -> float:
    low, high = span or RANGES[label]
    return float(low * (high / low) ** strength)


#: Effects set by their one parameter.
_SINGLE = {"coulomb_friction": "F_f", "cubic_stiffness": "k3", "sensor_inertia": "m_s",
           "hysteresis": "F_h"}


def effect_setting(spec: CaseSpec, truth: Mapping[str, float], rng: np.random.Generator,
                   mean_pressure: float) -> tuple[dict[str, Any], dict[str, float]]:
    """The effect's physical parameters for `spec`, and the truth (``F_0`` moved by
    ``contact_loss``)."""
    label, s, truth = spec.label, spec.strength, dict(truth)
    value = _scaled(label, s) if label in RANGES else 0.0
    masses = 2 if spec.family == "two-mass" else 3
    target = "p" if spec.inputs == 2 and rng.uniform() < 0.4 else "eta"
    if label in _SINGLE:
        return {_SINGLE[label]: value}, truth
    if label == "dead_zone":
        return {"w": value, "centre": plants.RELAXED_HEIGHT}, truth
    if label == "input_delay":
        return {"tau": value, "target": target}, truth
    if label == "actuator_lag":
        return {"T": value if target == "eta" else _scaled(label, s, BELLOW_LAG),
                "target": target}, truth
    if label == "extra_mode":
        j = masses - 1 if rng.uniform() < 0.6 else masses - 2
        m_e = value * truth[f"m{j + 1}"]
        omega = 2.0 * math.pi * rng.uniform(3.0, 12.0)
        return {"mass": j, "mu": value, "m_e": m_e, "k_e": m_e * omega ** 2,
                "c_e": 2.0 * 0.03 * m_e * omega}, truth
    if label == "contact_loss":
        static = truth["p_gain"] * mean_pressure + truth["F_0"]
        truth["F_0"] += (value - 1.0) * static
        return {"preload_scale": value}, truth
    if label == "offset":
        return {"d": value, "sign": float(rng.choice([-1.0, 1.0]))}, truth
    if label in ("saturation", "sign_blind_sensor"):
        sensed = "y_cb" if label == "sign_blind_sensor" and "y_cb" in spec.outputs else "F_c"
        return {"share": value, "target": sensed}, truth
    if label == "creep":
        return {"k_m": value * truth["k2"], "ratio": value, "tau_m": rng.uniform(1.0, 5.0)}, truth
    if label == "time_varying_gain":
        return {"g": value, "period": spec.duration * rng.uniform(0.5, 1.5),
                "phases": tuple(rng.uniform(0.0, 2.0 * math.pi, 2))}, truth
    return {}, truth


def level_setting(plant: EffectPlant, measured: Mapping[str, np.ndarray]) -> EffectPlant:
    """Saturation and sign-blind sensors: the level from the training run's noise-free signal
    (the share of samples above ``F_sat``, or below the fold ``reference``)."""
    s = dict(plant.setting)
    if plant.effect == "saturation":
        s["F_sat"] = float(np.quantile(measured["F_c"], 1.0 - s["share"]))
    elif plant.effect == "sign_blind_sensor":
        s["reference"] = float(np.quantile(measured[s["target"]], s["share"]))
    else:
        return plant
    return replace(plant, setting=s)


def excitation(name: str, rng: np.random.Generator, time: np.ndarray, rate: float,
               inputs: int) -> tuple[np.ndarray, np.ndarray]:
    """Wire height ``eta`` [m] and pressure ``p`` [bar] of one realisation of `name`."""
    top = min(20.0, 0.2 * rate)
    y_0 = plants.RELAXED_HEIGHT
    if name == "aprbs":
        eta = y_0 + plants._aprbs(rng, time, *(rng.uniform(0.005, 0.015) * np.array([-1, 1])),
                                  (0.05, 1.0))
        p = plants._aprbs(rng, time, 3.5, 5.5, (2.0, 8.0))
    elif name == "multisine":
        eta = y_0 + plants._multisine(rng, time, (0.1, top), rng.uniform(0.002, 0.005))
        p = 4.5 + plants._multisine(rng, time, (0.05, 1.0), 0.3)
    elif name == "chirp":
        eta = y_0 + plants._chirp(time, (rng.uniform(0.1, 0.3), top), rng.uniform(0.003, 0.005))
        p = 4.5 + 0.5 * np.sin(2.0 * math.pi * rng.uniform(0.05, 0.2) * time
                               + rng.uniform(0, 2 * math.pi))
    elif name == "ramps":
        eta = y_0 + _ramps(rng, time, 0.015, (0.2, 2.0), (0.3, 3.0))
        p = 4.5 + _ramps(rng, time, 1.0, (1.0, 4.0), (2.0, 6.0))
    else:
        raise ValueError(f"unknown excitation {name!r}; choose from {EXCITATIONS}")
    return eta, (p if inputs == 2 else np.full_like(time, 4.5))


def _ramps(rng: np.random.Generator, time: np.ndarray, level: float, ramp: tuple[float, float],
           hold: tuple[float, float]) -> np.ndarray:
    """Trapezoids: ramps of `ramp` [s] between levels uniform in +-`level`, holds of `hold` [s]."""
    knots_t, knots_y, t = [time[0]], [0.0], time[0]
    while t < time[-1]:
        t += rng.uniform(*hold)
        knots_t.append(t), knots_y.append(knots_y[-1])
        t += rng.uniform(*ramp)
        knots_t.append(t), knots_y.append(rng.uniform(-level, level))
    return np.interp(time, knots_t, knots_y)


@dataclass(frozen=True)
class EffectCase:
    """One case: the spec, the plant, both runs (noisy and noise-free) and the detectability.

    ``runs`` holds two dicts (training, validation) with ``time`` [s], ``eta`` [m], ``p`` [bar],
    ``outputs`` (noisy), ``clean`` (noise-free with the effect) and ``noise_std``; the validation
    run also ``nominal`` (noise-free, same parameters, no effect); ``detectability`` is per
    output [fit points]. An unscored case (``effect_case(..., scored=False)``) has no
    ``nominal`` run and empty ``detectability`` and ``step_drift``.
    """

    spec: CaseSpec
    plant: EffectPlant
    runs: tuple[dict, dict]
    detectability: Mapping[str, float]
    ceiling: Mapping[str, float] = field(default_factory=dict)
    """Per output: the fit [%] of the noise-free plant (with the effect) on the noisy validation
    data, the best any model can reach."""
    step_drift: Mapping[str, float] = field(default_factory=dict)
    """Per output: the ceiling less the fit of the same plant integrated with half the step
    [fit points]. Near zero for a plant whose free run is reproducible; large where tiny
    differences grow (a head bouncing on the wire: each impact's timing shifts the next), and
    there no model's free run can reach the ceiling, which only the identical integration
    reproduces (:attr:`reproducible`)."""

    @property
    def reproducible(self) -> bool:
        """Whether halving the integration step moves the true plant's validation fit by less
        than 2 fit points on every output (the strength threshold of the benchmark); an output
        whose fit is undefined (a head that flies for the whole run reads a constant zero) does
        not count against it. An unscored case (``effect_case(..., scored=False)``) raises."""
        self._scored()
        return not any(abs(v) >= 2.0 for v in self.step_drift.values())

    @property
    def strongest(self) -> float:
        """The largest detectability over the outputs [fit points] (an unscored case raises)."""
        self._scored()
        return max(self.detectability.values())

    def _scored(self) -> None:
        if not self.detectability or not self.step_drift:
            raise ValueError(f"{self.spec.name}: an unscored case (effect_case(..., "
                             "scored=False)) has no detectability and no step drift")


def fit(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Fit [%] ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)``."""
    return float(100.0 * (1.0 - np.linalg.norm(measured - simulated)
                          / np.linalg.norm(measured - np.mean(measured))))


def effect_case(spec: CaseSpec, *, scored: bool = True) -> EffectCase:
    """Simulate `spec`'s plant on a training and a validation realisation (module notes).

    `scored` False leaves out the two runs only the benchmark's scores need (the validation run
    without the effect, for :attr:`EffectCase.detectability`, and at half the step, for
    :attr:`EffectCase.step_drift`; both left empty): the runs, the plant and the ceiling are the
    same (a test that diagnoses one case needs no more; they cost 3/5 of a case's simulation)."""
    rng = np.random.default_rng([stable_hash(spec.name), 1])
    masses = 2 if spec.family == "two-mass" else 3
    truth = plants.draw_oscillator_truth(masses, rng)
    time = np.arange(int(round(spec.duration * spec.rate))) / spec.rate
    signals = [excitation(spec.excitation, rng, time, spec.rate, spec.inputs) for _ in range(2)]
    setting, truth = effect_setting(spec, truth, rng, float(np.mean(signals[0][1])))
    plant = EffectPlant(truth, spec.label, setting)
    nominal = EffectPlant(truth)
    runs = []
    for index, (eta, p) in enumerate(signals):
        raw = plant.simulate(time, eta, p)
        if index == 0:
            plant = level_setting(plant, plant.measure(raw, time, 0, ("F_c", "y_cb", "xi")))
        clean = plant.measure(raw, time, index, spec.outputs)
        noisy, sigma = plants.add_noise(clean, spec.snr_db, rng)
        runs.append({"time": time, "eta": eta, "p": p, "outputs": noisy, "clean": clean,
                     "noise_std": sigma})
    validation = runs[1]
    ceiling = {name: fit(validation["outputs"][name], validation["clean"][name])
               for name in spec.outputs}
    if not scored:
        return EffectCase(spec, plant, (runs[0], runs[1]), {}, ceiling, {})
    runs[1]["nominal"] = runs[1]["clean"] if spec.label == "clean" else \
        nominal.measure(nominal.simulate(time, *signals[1]), time, 1, spec.outputs)
    detectability = {name: ceiling[name] - fit(validation["outputs"][name],
                                               validation["nominal"][name])
                     for name in spec.outputs}
    half = plant.measure(plant.simulate(time, *signals[1], step=0.5 * plant.step_limit()), time,
                         1, spec.outputs)
    drift = {name: ceiling[name] - fit(validation["outputs"][name], half[name])
             for name in spec.outputs}
    return EffectCase(spec, plant, (runs[0], runs[1]), detectability, ceiling, drift)
