"""The candidate ranking of :func:`panto.identification.diagnosis.pipeline.diagnose` on the training residual:
FROLS error-reduction ratios of the effects' physical regressors (:func:`panto.identification.diagnosis.effects.
rank_effects`), each regressor taken as it reaches the outputs (through a linear output-error
model's filter, or through the nominal's own response to the input it enters,
:func:`input_paths`), and the start settings of the augmentations the refits begin from.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.diagnosis.augmentations import (INPUT_SIDE, equivalent_input,
                                                          mode_carrier, simulating)
from panto.identification.estimation.base import IdentificationData, IdentificationError, ModelStructure
from panto.identification.diagnosis.support import residuals, sensitivities
from panto.identification.structures.oscillators import (OUTPUT_NAMES, OscillatorStructure,
                                                       discretise, propagate)
from panto.identification.diagnosis.effects import (SignalRoles, build_candidate_regressors, filter_sensitivity,
                                    friction_regressors,
                                    name_signals, rank_effects, sensor_acceleration,
                                    sensor_signal)

# --- the ranking on the training residual -----------------------------------------------------

def _bare_nominal(structure: ModelStructure) -> ModelStructure:
    """The nominal under every augmentation (through an inside form's base, else its
    ``nominal_structure``); not :func:`augmentations._innermost`, which stops at the first
    structure that is not an :class:`AugmentedStructure`."""
    while hasattr(structure, "nominal_structure"):
        structure = structure.base if getattr(structure, "mode", "") == "inside" else \
            structure.nominal_structure
    return structure


def _output_filter(structure: ModelStructure, parameters: Mapping[str, float], output: str,
                   drive: str):
    from panto.identification.structures.output_error import LinearOutputError

    inner = _bare_nominal(structure)
    if not isinstance(inner, LinearOutputError):
        return None
    f, b = inner.polynomials({k: v for k, v in parameters.items()
                              if k in inner.parameter_names}, output)
    return filter_sensitivity(b[drive], f)


def rank_candidates(model: Any, train: IdentificationData, roles: SignalRoles,
                    candidates: Sequence[str], max_refits: int,
                    every: Sequence[str] = ()) -> dict[str, Any]:
    """FROLS ranking per output of the current model's training residual; the top candidates
    with start settings for their augmentation.

    The ranking screens, the refit judges: the `max_refits` refits go to the significant
    candidates first, then to the best of the rest (ERR >= :data:`MIN_ERR`), each ordered by
    its ERR summed over the outputs (each output's ERR is a share of that output's residual
    energy; one physical cause should explain the gap in every output it reaches), because an effect
    the nominal has partly absorbed shows a weak signature on the training residual (its
    projection on the nominal's sensitivities is removed) yet can still be the one that closes
    the gap once refitted in the model. Input-side effects count per input.

    The effects in `every` are refitted whatever their ERR, each on every input it can enter
    (its best variant there), after the `max_refits` (the search asks for this when the linear
    black box shows dynamics the model lacks:
    :func:`~panto.identification.diagnosis.refit.lacks_linear_dynamics`). The rivals
    (:data:`RIVALS`) of a ranked candidate follow them, whatever their ERR (``"rivals"`` names
    them). A sensor mass offered at two placements (the wire's and the head's) carries the
    other one as ``other_placement`` (its variant and setting), refitted beside it
    (:func:`~panto.identification.diagnosis.refit.try_candidate`).

    A regressor is scored as it reaches the output: through the linear OE model's filter, or,
    for any other nominal, through the nominal's own response to the input it enters
    (:func:`input_paths`: delays, lags, dead zones and saturations of an input, and effects with an
    equivalent input); output-side signatures are scored as they are."""
    y_hat, eps = residuals(model.structure, model.parameters, train)
    signals = name_signals(train.inputs, train.input_names, y_hat, train.output_names)
    head = head_signal(model, train, roles, signals) if "sensor_inertia" in candidates else None
    if head is not None:
        signals[roles.head_position] = head
    regressors = {k: v for k, v in build_candidate_regressors(
        signals, train.sample_period, roles=roles).items() if k in candidates}
    if not regressors:
        return {"top": [], "per_output": {}, "appended": 0}
    jac = sensitivities(model.structure, model.parameters, model.free, train)
    drive = next((a for a in roles.actuators if a in train.input_names), train.input_names[0])
    paths = {} if _output_filter(model.structure, model.parameters, train.output_names[0],
                                 drive) else input_paths(model, train, regressors, y_hat)
    if "coulomb_friction" in regressors:
        on_masses, mass_paths = mass_friction(model, train)
        regressors["coulomb_friction"] = {**regressors["coulomb_friction"], **on_masses}
        paths.update(mass_paths)
    if "cubic_stiffness" in regressors:
        on_springs, spring_paths = spring_stiffening(model, train)
        centres = next((setting["centres"] for _, setting in on_springs.values()), None) \
            or spring_centres(model, train)  # every variant's inside form: the same laws
        centres = {} if centres is None else {"centres": centres}
        regressors["cubic_stiffness"] = {
            **{k: (x, {**setting, **centres}) for k, (x, setting)
               in regressors["cubic_stiffness"].items()}, **on_springs}
        paths.update(spring_paths)
    best: dict[str, dict[str, Any]] = {}
    total: dict[str, float] = {}
    extra: dict[str, dict[str, Any]] = {}  # `every`'s keys below MIN_ERR
    extra_total: dict[str, float] = {}
    per_output = {}
    context = _Context(model, train, roles, signals, drive)
    for j, output in enumerate(train.output_names):
        if not np.any(eps[:, j]):
            continue
        if paths:
            regressors = {e: {v: (paths[(e, v)][:, j] if (e, v) in paths else x, setting)
                              for v, (x, setting) in variants.items()}
                          for e, variants in regressors.items()}
        ranked = _rank_output(context, output, eps[:, j], jac[:, j, :] if jac.shape[2] else None,
                              regressors)
        if ranked is None:
            continue
        per_output[output] = ranked.ranking.to_dict()
        for score in ranked.ranking.first_step:
            key = score.effect
            if score.err >= MIN_ERR:
                table, sums = best, total
            elif key.split("@")[0] in (*every, *RIVAL_EFFECTS) and np.isfinite(score.err):
                table, sums = extra, extra_total  # kept apart: the ranked head stays as it was
            else:
                continue
            score = dataclasses.replace(score, effect=key.split("@")[0])
            sums[key] = sums.get(key, 0.0) + float(score.err)
            if key not in table or (score.significant, score.err) > (
                    table[key]["significant"], table[key]["err"]):
                table[key] = _candidate(context, ranked, key, score)
    for table, sums in ((best, total), (extra, extra_total)):
        for key, candidate in table.items():
            candidate["err_total"] = sums[key]
    top = sorted(best.values(), key=lambda c: (not c["significant"], -c["err_total"]))
    chosen = top[:max_refits]
    keys = sorted({k for k in (*best, *extra) if k.split("@")[0] in every})
    appended = sorted((c for c in (best.get(k, extra.get(k)) for k in keys)
                       if all(c is not other for other in chosen)),
                      key=lambda c: (not c["significant"], -c["err_total"]))
    rivals = [best.get(k, extra.get(k)) for k in sorted({
        r for c in chosen for r in RIVALS.get(c["effect"], ()) if r in best or r in extra})]
    rivals = [c for c in rivals if all(c is not other for other in chosen + appended)]
    return {"top": chosen + appended + rivals, "per_output": per_output,
            "appended": len(appended), "rivals": [c["effect"] for c in rivals]}


def head_signal(model: Any, data: IdentificationData, roles: SignalRoles,
                signals: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The head's position (``roles.head_position``) as the current model simulates it on
    `data`, when the data do not measure it; None when they do, when the roles name no head
    or when the structure cannot simulate it (a black box, a rigid body)."""
    head = roles.head_position
    twin = None if head is None or head in signals else simulating(model.structure, head)
    if twin is None:
        return None
    try:
        y = np.asarray(twin.simulate(model.parameters, data), float)
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    if y.ndim != 2 or y.shape[1] != len(data.output_names) + 1 or \
            not np.all(np.isfinite(y[:, -1])):
        return None
    return y[:, -1]


@dataclasses.dataclass(frozen=True, eq=False)
class _Context:
    """What every output's ranking shares: the current model, the training run, the signal roles,
    the named signals the regressors are built from, and the input that drives the model."""

    model: Any
    train: IdentificationData
    roles: SignalRoles
    signals: Mapping[str, np.ndarray]
    drive: str


@dataclasses.dataclass(frozen=True, eq=False)
class _OutputRanking:
    """One output's FROLS ranking and what its candidates' start settings are computed from."""

    output: str
    target: np.ndarray
    base: np.ndarray | None
    sensitivity: Any
    split: dict[str, dict[str, Any]]
    ranking: Any


def _rank_output(context: _Context, output: str, target: np.ndarray, base: np.ndarray | None,
                 regressors: Mapping[str, Mapping[str, Any]]) -> _OutputRanking | None:
    """FROLS on one output's residual `target`, the nominal's sensitivities `base` projected
    out (None when the ranking fails)."""
    if base is not None:
        base = base[:, np.linalg.norm(base, axis=0) > 0]
    model = context.model
    sensitivity = _output_filter(model.structure, model.parameters, output, context.drive)
    split = _split_per_input(regressors)
    try:
        ranking = rank_effects(target, split, base=base, sensitivity=sensitivity)
    except IdentificationError:
        return None
    return _OutputRanking(output, target, base, sensitivity, split, ranking)


def _candidate(context: _Context, ranked: _OutputRanking, key: str, score: Any) -> dict[str, Any]:
    """A candidate for refitting: its effect, variant, ERR and the augmentation's start setting."""
    coefficient = _coefficient(ranked.split[key][score.variant][0], ranked.target, ranked.base,
                               ranked.sensitivity)
    setting = _setting(score, ranked.output, coefficient, context.signals, context.train,
                       context.roles, context.drive)
    through = equivalent_input(context.model.structure, score.effect)
    if through:
        setting["input_scale"] = float(np.std(context.train.input(through))) or 1.0
    candidate = {"effect": score.effect, "variant": score.variant, "err": float(score.err),
                 "significant": bool(score.significant), "output": ranked.output,
                 "setting": setting}
    if score.effect == "sensor_inertia":
        other = next((label for label, (_, v_setting) in sorted(ranked.split[key].items())
                      if v_setting.get("signal") not in (None, setting.get("signal"))
                      and v_setting.get("signal") in context.signals), None)
        if other is not None:  # the other placement (the wire's or the head's), refitted beside
            there = dataclasses.replace(score, variant=other,
                                        setting=dict(ranked.split[key][other][1]))
            coefficient = _coefficient(ranked.split[key][other][0], ranked.target, ranked.base,
                                       ranked.sensitivity)
            candidate["other_placement"] = {
                "variant": other, "setting": _setting(there, ranked.output, coefficient,
                                                      context.signals, context.train,
                                                      context.roles, context.drive)}
    carrier = mode_carrier(context.model.structure) if score.effect == "extra_mode" else None
    if carrier is not None:  # the mode as a mass hung on the head, refitted beside the outside one
        candidate["other_placement"] = {"variant": f"extra mass on mass {carrier}",
                                        "setting": {**setting, "attached": carrier}}
    return candidate


def mass_friction(model: Any, train: IdentificationData
                  ) -> tuple[dict[str, tuple[np.ndarray, dict]], dict[tuple[str, str], np.ndarray]]:
    """Friction on each mass of an oscillator nominal (the inside form fits one on every mass):
    the regressors ``sign(v_i)``, ``tanh(v_i / v_s)`` of the nominal's own simulated velocity of
    mass ``i`` and their paths to the outputs, the response of the nominal's linear dynamics to
    that force on mass ``i`` (exact for inputs linear between samples). The measured position's
    velocity is mass ``n-1``'s on a three-mass oscillator (``y_cb``), not the frame's, and a
    force on a mass reaches the outputs only through the dynamics. Empty for other nominals."""
    run = _oscillator_run(model, train)
    if run is None:
        return {}, {}
    n = run.masses.size
    regressors, paths = {}, {}
    for i in range(n):
        force = np.zeros((run.a.shape[0], 1))  # an extra mass's states follow
        force[n + i, 0] = 1.0 / run.masses[i]
        for label, (x, setting) in friction_regressors(run.states[:, n + i]).items():
            key = label.replace("(v", f"(v{i + 1}", 1)
            regressors[key] = (x, {**setting, "mass": i + 1})
            paths[("coulomb_friction", key)] = run.path(force, x)
    return regressors, paths


def spring_stiffening(model: Any, train: IdentificationData
                      ) -> tuple[dict[str, tuple[np.ndarray, dict]],
                                 dict[tuple[str, str], np.ndarray]]:
    """A hardening or softening spring of an oscillator nominal (the inside form fits a quadratic
    and a cubic term on every chain spring): the regressors ``(d_i - d_i0)^3`` and
    ``(d_i - d_i0)^2`` of the nominal's own simulated deflection of spring ``i`` (base-1, 1-2, ...;
    ``d_i0`` at the run's first sample, the operating point, given in every variant's setting
    as ``centres``: the inside form's fixed centres of the spring laws; the square is the larger
    part of a spring stiffening about its free length under a preload) and their paths to the
    outputs, the response of the nominal's linear dynamics to that spring's force (pulling mass
    ``i`` and, above the base, mass ``i-1`` the other way). A spring's force follows its
    deflection, which no measured position is when the data measure only the contact force or a
    position the spring does not span. Empty for other nominals, for an oscillator that holds
    spring terms already, and for one with friction (once ``coulomb_friction`` is accepted a
    cubic spring is ranked from the measured position's cube alone, as :func:`mass_friction` is
    empty there; :func:`spring_centres` then gives the centres)."""
    run = None if getattr(_bare_nominal(model.structure), "cubic", False) else \
        _oscillator_run(model, train)
    if run is None:
        return {}, {}
    n = run.masses.size
    deflections = np.diff(run.states[:, :n], axis=1, prepend=0.0)
    centres = tuple(float(d) for d in deflections[0])  # the spring laws' fixed centres
    regressors, paths = {}, {}
    for i in range(n):
        force = np.zeros((run.a.shape[0], 1))  # an extra mass's states follow
        force[n + i, 0] = -1.0 / run.masses[i]
        if i > 0:
            force[n + i - 1, 0] = 1.0 / run.masses[i - 1]
        stretch = deflections[:, i] - deflections[0, i]
        for power in (3, 2):
            key, x = f"d{i + 1}^{power}", stretch ** power
            regressors[key] = (x, {"spring": i + 1, "centres": centres})
            paths[("cubic_stiffness", key)] = run.path(force, x)
    return regressors, paths


def spring_centres(model: Any, train: IdentificationData) -> tuple[float, ...] | None:
    """The deflections [m] of an oscillator nominal's chain springs at rest at the training run's
    first input sample (the linear model's equilibrium: the fixed centres of the inside form's
    spring laws, :class:`~panto.identification.structures.oscillator_effects.
    NonlinearOscillator`); None for other nominals, for one holding spring terms already (it
    keeps its own centres) and where the nominal has no rest there."""
    inner = _bare_nominal(model.structure)
    if not isinstance(inner, OscillatorStructure) or getattr(inner, "cubic", False):
        return None
    values = {k: v for k, v in model.parameters.items() if k in inner.parameter_names}
    try:
        rest = OscillatorStructure.equilibrium(inner, values, float(train.input("eta")[0]),
                                               float(train.input("p")[0]))
    except (IdentificationError, KeyError, ValueError):
        return None
    return tuple(float(d) for d in np.diff(rest[:inner.masses], prepend=0.0))


@dataclasses.dataclass(frozen=True, eq=False)
class _OscillatorRun:
    """A linear oscillator nominal's free run on the training run: its states ``[z; z']``, its
    ``A``, the output rows of its ``C`` for the data's outputs, the masses and the hold."""

    states: np.ndarray
    a: np.ndarray
    c: np.ndarray
    masses: np.ndarray
    period: float
    hold: str

    def path(self, force: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The outputs of the linear dynamics from rest, driven by ``force * x(t)`` (exact for
        `x` linear between samples with ``hold="foh"``)."""
        phi, gamma0, gamma1 = discretise(self.a, force, self.period, self.hold)
        drive = x[:-1, None] @ gamma0.T + np.diff(x)[:, None] @ gamma1.T
        return propagate(phi, drive, np.zeros(self.a.shape[0])) @ self.c.T


def _oscillator_run(model: Any, train: IdentificationData) -> _OscillatorRun | None:
    """The :class:`_OscillatorRun` of `model`'s nominal, None when it is not a friction-free
    oscillator or cannot run."""
    inner = _bare_nominal(model.structure)
    if not isinstance(inner, OscillatorStructure) or inner.friction:
        return None
    values = {k: v for k, v in model.parameters.items() if k in inner.parameter_names}
    try:
        states = inner.states(values, train)
        a, _, c, _ = inner.matrices(values)
        masses = np.array([inner.values(values)[f"m{i + 1}"] for i in range(inner.masses)])
    except (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    rows = [OUTPUT_NAMES.index(o) for o in train.output_names]
    return _OscillatorRun(states, a, c[rows], masses, train.sample_period, inner.hold)


#: Smallest error-reduction ratio for a candidate to be refitted at all.
MIN_ERR = 0.005

#: Effects refitted whenever the ranked head holds the key, whatever their ERR: rival
#: explanations of the same signature, the simpler one never left untried. A mass on the force
#: sensor bends the force's response at high frequency as an extra mode does, with one parameter
#: instead of three (seen held-out two-mass/sensor_inertia/2076: ranked sixth behind an extra
#: mode, never refitted, and the mode was named).
RIVALS = {"extra_mode": ("sensor_inertia",)}
RIVAL_EFFECTS = tuple(sorted({r for group in RIVALS.values() for r in group}))


def _split_per_input(regressors: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """Input-side effects as one candidate per input (``actuator_lag@p``): a lag on the pressure
    and a lag on the slider height are different hypotheses, ranked and refitted separately."""
    split: dict[str, dict[str, Any]] = {}
    for effect, variants in regressors.items():
        for label, (x, setting) in variants.items():
            where = setting.get("input") if effect in INPUT_SIDE else None
            split.setdefault(f"{effect}@{where}" if where else effect, {})[label] = (x, setting)
    return split


def _coefficient(x: np.ndarray, target: np.ndarray, base: np.ndarray | None, sensitivity) -> float:
    x = sensitivity(x) if sensitivity else np.asarray(x, float)
    r = np.asarray(target, float)
    if base is not None and base.shape[1]:
        q, _ = np.linalg.qr(base)
        x, r = x - q @ (q.T @ x), r - q @ (q.T @ r)
    xx = float(x @ x)
    return float(x @ r / xx) if xx > 0 else 0.0


def _setting(score: Any, output: str, coefficient: float, signals: Mapping[str, np.ndarray],
             data: IdentificationData, roles: SignalRoles, drive: str) -> dict[str, Any]:
    y = signals[output]
    setting = {**dict(score.setting), "output": output, "coefficient": coefficient,
               "scale": float(np.std(y)) or 1.0, "nyquist": 0.5 / data.sample_period,
               "drive": score.setting.get("drive", drive), "start": coefficient,
               "native_start": abs(coefficient) if score.effect == "coulomb_friction" else 0.0,
               "max_delay_s": 0.1 * (data.time[-1] - data.time[0])}
    position = signals.get(roles.position) if roles.position else None
    if position is not None:
        setting["centre"] = float(np.median(position))
        setting["position_scale"] = float(np.std(position)) or 1.0
    sensor = score.setting.get("signal") if score.effect == "sensor_inertia" else None
    sensor = sensor if sensor in signals else sensor_signal(roles, list(signals))
    if sensor is not None:  # the acceleration sensor_inertia's mass follows (its bound's scale)
        setting["acceleration_scale"] = float(np.std(sensor_acceleration(
            signals[sensor], data.sample_period))) or 1.0
    signal = setting.get("signal") or setting.get("input")
    if score.effect == "dead_zone":  # the input the augmentation transforms (its _input)
        zone = signal if signal in data.input_names else next(
            (a for a in roles.actuators if a in data.input_names), data.input_names[0])
        median = float(np.median(data.input(zone)))
        setting["centre"] = float(score.setting.get("centre", median))
        setting["spread"] = float(np.max(np.abs(data.input(zone) - setting["centre"])))
    if setting["drive"] not in data.input_names and score.effect != "extra_mode":
        setting["drive"] = drive
    phi_scale = {"cubic_stiffness": setting.get("position_scale", 1.0) ** 3}.get(score.effect, 1.0)
    u_scale = float(np.std(signals[drive])) if drive in signals else 1.0
    setting["bound"] = 100.0 * max(abs(coefficient), u_scale / max(phi_scale, 1e-30))
    return setting


# --- how a regressor reaches the outputs ------------------------------------------------------

#: CPU time [s] the directional responses of :func:`input_paths` may take per ranking (CPU, not
#: wall time: on a loaded machine the wall clock tripped it and changed the ranking, measured on
#: ``benchmarks/diagnosis_speed.py`` at load 14 on 2 cores: round 3's candidates differed).
PATH_BUDGET = 20.0


def input_paths(model: Any, data: IdentificationData,
                regressors: Mapping[str, Mapping[str, tuple[np.ndarray, dict]]],
                y_hat: np.ndarray) -> dict[tuple[str, str], np.ndarray]:
    """The nominal's response to each input-entering regressor, ``(N, n_outputs)`` per
    ``(effect, variant)``: ``(y_hat(u_a + h phi) - y_hat(u)) / h``, the directional derivative of
    the free run along ``phi`` added to input ``a`` (the input a delay, lag, dead zone or
    saturation transforms, or the effect's equivalent input,
    :func:`~panto.identification.diagnosis.augmentations.equivalent_input`). A term that enters an input reaches
    an output only through the model's dynamics; scored raw, a lag of the bellow pressure would
    look like nothing the force residual holds. ``h`` is 1 % of the input's spread over the
    regressor's. Empty when the simulations would exceed :data:`PATH_BUDGET` of CPU time (one
    timed first)."""
    structure, parameters = model.structure, model.parameters
    jobs = []
    for effect, variants in regressors.items():
        for label, (x, setting) in variants.items():
            name = equivalent_input(structure, effect) if effect not in INPUT_SIDE else \
                (setting.get("input") or setting.get("signal"))
            if name in data.input_names:
                jobs.append(((effect, label), name, np.asarray(x, float)))
    out: dict[tuple[str, str], np.ndarray] = {}
    started = time.process_time()
    for count, (key, name, x) in enumerate(jobs):
        if count == 1 and (time.process_time() - started) * len(jobs) > PATH_BUDGET:
            return {}
        spread = float(np.std(x))
        if not spread > 0:
            continue
        index = data.input_names.index(name)
        h = 0.01 * (float(np.std(data.inputs[:, index])) or 1.0) / spread
        inputs = np.array(data.inputs, float)
        inputs[:, index] += h * x
        try:
            y1, _ = residuals(structure, parameters, dataclasses.replace(data, inputs=inputs))
        except (IdentificationError, ValueError, ArithmeticError):
            continue
        out[key] = (y1 - y_hat) / h
    return out


__all__ = ["rank_candidates", "input_paths", "head_signal", "mass_friction",
           "spring_stiffening", "MIN_ERR", "PATH_BUDGET", "RIVALS"]
