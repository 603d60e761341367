"""The blind benchmark of the sim-to-real diagnosis on the virtual test bed: the diagnosis proven on
data whose effect is withheld.

:func:`run_diagnosis_benchmark` ``(cases, seed)`` draws cases (:func:`draw_cases`), each with ONE
hidden effect of random magnitude on an otherwise ideal test bed (sensor noise only), or none, or
one outside the effect library; records a training run and a *different* validation run (another
APRBS realisation: profile seed and noise seed differ); diagnoses them blind (the datasets' truth
metadata is stripped before :func:`panto.identification.diagnosis.pipeline.diagnose` sees them); and scores.

Hidden effects, mapped to the test bed (:class:`panto.rig.imperfections.RigImperfections`):

=================  ==========================================================================
label              test bed
=================  ==========================================================================
coulomb_friction   ``hinge_friction_torque`` (lower-arm hinge, N m)
cubic_stiffness    ``head_stiffening`` (head suspension, N/m^3)
sensor_inertia     ``bar_mass`` (bar between force sensor and pantograph, kg)
actuator_lag       ``bellow_lag`` (valve -> bellow first-order lag, s)
input_delay        ``bellow_delay`` (valve -> bellow transport delay, s)
extra_mode         ``robot_compliance`` / ``robot_frequency`` (the robot carrying the motor)
contact_loss       ``unilateral_contact`` (the head loses contact when the bar falls faster than
                   it can follow: only on the fast profile)
offset             ``force_offset`` (N) or ``laser_offset`` (m), one of the two at random
hysteresis         outside the library: the recorded force passed through a force-sensor
                   hysteresis ``F + h (P_w(F) - F)``, ``P_w`` the play operator of half-width
                   ``w`` (post-processing of the recorded 500 Hz force, documented emulation)
gain_drift         outside the library: the force sensor's gain drifts linearly over the run,
                   ``F (1 + g (t / T - 1/2))`` (post-processing)
none               no effect
=================  ==========================================================================

Each case's motor profile is drawn independently of its label (:data:`FAST_SHARE`): the
training APRBS of the thesis (1 Hz conditioning) or a fast one (larger motor steps held
0.3-1 s, 8 Hz conditioning) where inertia, stiffening and contact loss show. Tying the fast
profile to one label would let the profile itself tell the label.

``dead_zone`` and ``saturation`` are left out of the draw: the test bed has no dead zone or
saturation between the *measured* inputs and the outputs (the valve's dead band and saturation sit
before the pressure sensor, so the model never sees them).

Scores (:class:`BenchmarkResult`):

- the *cost* of a hidden effect is what it costs the nominal model: twins of the training and
  validation runs with the effect off (same seeds, same noise) give ``f_clean``, the validation
  fit of the nominal fitted on the clean twin training run; the cost is the largest drop
  ``f_clean - f_before`` over the outputs, ``f_before`` the diagnosed nominal's validation fit.
  An effect the nominal's parameters absorb (a force offset taken up as preload) costs little
  however large its signal: there is no gap to diagnose. The effect's own contribution
  ``y_with - y_without`` is kept as ``signal_cost = 100 - fit(y_with, y_without)`` (thesis
  eq. 4.1.3) for the record;
- confusion matrix (true label x predicted first effect / ``none`` / ``unexplained``);
- top-1 accuracy on library effects costing >= ``strong`` (5) fit points;
- false alarms on ``none`` (an effect named), and ``none`` recognised;
- ``unexplained`` rate on out-of-library effects;
- gap closed on validation: the share of the gap to the effect-free nominal removed by the
  accepted effect(s), in normalised residual energy,
  ``sum_o [(1 - f_before/100)^2 - (1 - f_after/100)^2] / sum_o [(1 - f_before/100)^2 -
  (1 - f_clean/100)^2]`` (:func:`gap_closed`), on correctly named strong cases.
"""
from __future__ import annotations

import dataclasses
import math
import tempfile
import time
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

if TYPE_CHECKING:  # imported where used: the tests wrap pipeline.diagnose
    from panto.identification.diagnosis.pipeline import DiagnosisOptions

Progress = Callable[[str], None]
#: Library effects the test bed can hide (see the module notes for the mapping).
LIBRARY_DRAW = ("coulomb_friction", "cubic_stiffness", "sensor_inertia", "actuator_lag",
                "input_delay", "extra_mode", "contact_loss", "offset")
#: The test bed's imperfections (:class:`panto.rig.imperfections.RigImperfections` fields) each library
#: effect names (the module notes' table).
IMPERFECTIONS_OF = {"coulomb_friction": ("hinge_friction_torque",),
                    "cubic_stiffness": ("head_stiffening",), "sensor_inertia": ("bar_mass",),
                    "actuator_lag": ("bellow_lag",), "input_delay": ("bellow_delay",),
                    "extra_mode": ("robot_compliance",), "contact_loss": ("unilateral_contact",),
                    "offset": ("force_offset", "laser_offset")}
#: Effects outside the library (emulated by post-processing the recorded force).
OUTSIDE_DRAW = ("hysteresis", "gain_drift")
#: Share of the draw per kind: library effect, none, outside.
KIND_WEIGHTS = {"library": 0.6, "none": 0.2, "outside": 0.2}
#: Magnitude ranges (log-uniform unless noted) of each hidden effect.
MAGNITUDES = {"coulomb_friction": (5.0, 60.0), "cubic_stiffness": (2e7, 4e8),
              "sensor_inertia": (1.0, 8.0), "actuator_lag": (0.05, 0.6),
              "input_delay": (0.03, 0.25), "extra_mode": (1e-6, 1e-5),
              "contact_loss": (1.0, 1.0), "offset": (1.0, 20.0), "laser_offset": (1e-3, 1e-2),
              "hysteresis": (0.2, 0.8), "gain_drift": (0.05, 0.3)}
#: Share of the cases recorded with the fast motor profile (module notes).
FAST_SHARE = 0.5
STRONG = 5.0
"""Fit points an effect must cost to count for the top-1 score."""


@dataclass(frozen=True)
class BenchmarkCase:
    """One drawn case: what is hidden, how strong, and the runs' seeds."""

    index: int
    kind: str
    """``library``, ``none`` or ``outside``."""
    label: str
    """The hidden effect's name (a library effect, ``none``, ``hysteresis``, ``gain_drift``)."""
    magnitude: float
    settings: Mapping[str, Any]
    """Test bed imperfections (or post-processing settings) that make the effect."""
    train_seed: int
    validation_seed: int
    fast_profile: bool = False
    """A faster, larger motor profile (module notes: drawn independently of the label)."""


@dataclass(frozen=True)
class CaseOutcome:
    """What the diagnosis said on one case and how it scores."""

    case: BenchmarkCase
    verdict: str
    effects: tuple[str, ...]
    predicted: str
    cost: float
    fit_before: Mapping[str, float]
    fit_after: Mapping[str, float]
    fit_effect: Mapping[str, float]
    gap_closed: float
    wall_time: float
    error: str = ""
    spread: Mapping[str, float] = field(default_factory=dict)
    """Standard deviation of each validation output (the scale of the fit metric)."""
    signal_cost: float = math.nan
    """Fit points of the effect's own contribution to the outputs (module notes)."""
    fit_clean: Mapping[str, float] = field(default_factory=dict)
    """Validation fit of the nominal fitted on the effect-free twin runs."""


@dataclass(frozen=True)
class BenchmarkResult:
    """The cases, their outcomes and the scores (module notes); :meth:`to_dict` is the JSON."""

    outcomes: tuple[CaseOutcome, ...]
    scores: Mapping[str, Any]
    confusion: Mapping[str, Mapping[str, int]]
    settings: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        from panto.identification.diagnosis.residual_energy import jsonable

        return jsonable({"scores": dict(self.scores), "confusion": dict(self.confusion),
                         "settings": dict(self.settings),
                         "cases": [_outcome_dict(o) for o in self.outcomes]})


def _outcome_dict(outcome: CaseOutcome) -> dict[str, Any]:
    values = dataclasses.asdict(outcome)
    values["case"] = dataclasses.asdict(outcome.case)
    return values


# --- drawing the cases ------------------------------------------------------------------------

def draw_cases(count: int, seed: int, *,
               kinds: Mapping[str, float] = KIND_WEIGHTS) -> tuple[BenchmarkCase, ...]:
    """`count` cases from `seed`: the kinds in proportion to `kinds` (stratified, then shuffled),
    library and outside effects cycled through in a shuffled order, magnitudes log-uniform."""
    if count < 1:
        raise ValueError(f"cases = {count!r}: must be >= 1")
    rng = np.random.default_rng(seed)
    shares = np.array([kinds[k] for k in ("library", "none", "outside")], float)
    numbers = np.floor(shares / shares.sum() * count).astype(int)
    for k in np.argsort(-shares)[: count - numbers.sum()]:
        numbers[k] += 1
    labels = ([_cycle(LIBRARY_DRAW, numbers[0], rng), ["none"] * numbers[1],
               _cycle(OUTSIDE_DRAW, numbers[2], rng)])
    kinds_list = [("library", l) for l in labels[0]] + [("none", l) for l in labels[1]] + \
        [("outside", l) for l in labels[2]]
    order = rng.permutation(len(kinds_list))
    cases = []
    for index, k in enumerate(order):
        kind, label = kinds_list[k][0], str(kinds_list[k][1])
        magnitude, settings = _settings(label, rng)
        cases.append(BenchmarkCase(index, kind, label, magnitude, settings,
                                   int(rng.integers(1, 2**31 - 1)), int(rng.integers(1, 2**31 - 1)),
                                   fast_profile=bool(rng.random() < FAST_SHARE)))
    return tuple(cases)


def _cycle(labels: Sequence[str], count: int, rng: np.random.Generator) -> list[str]:
    out: list[str] = []
    while len(out) < count:
        out += list(rng.permutation(labels))
    return out[:count]


def _settings(label: str, rng: np.random.Generator) -> tuple[float, dict[str, Any]]:
    if label == "none":
        return 0.0, {}
    sensor = str(rng.choice(["force", "laser"])) if label == "offset" else ""
    low, high = MAGNITUDES["laser_offset" if sensor == "laser" else label]
    value = float(math.exp(rng.uniform(math.log(low), math.log(high))))
    if label in ("offset",):
        value *= float(rng.choice([-1.0, 1.0]))
    settings: dict[str, Any] = {
        "coulomb_friction": {"hinge_friction_torque": value},
        "cubic_stiffness": {"head_stiffening": value},
        "sensor_inertia": {"bar_mass": value},
        "actuator_lag": {"bellow_lag": value},
        "input_delay": {"bellow_delay": value},
        "extra_mode": {"robot_compliance": value, "slider_mass": 3.0,
                       "robot_frequency": float(rng.uniform(4.0, 12.0)),
                       "robot_damping_ratio": 0.05},
        "contact_loss": {"unilateral_contact": True},
        "offset": {f"{sensor}_offset": value},
        "hysteresis": {"hysteresis_share": value, "hysteresis_width": 0.3},
        "gain_drift": {"gain_drift": value},
    }[label]
    return value, settings


# --- one case ------------------------------------------------------------------------------

def run_case(case: BenchmarkCase, *, duration: float = 25.0, structure: str = "physical-linear",
             folder: str | None = None, diagnose_options: DiagnosisOptions | None = None
             ) -> CaseOutcome:
    """Record the case's runs, diagnose them blind and score the outcome (module notes)."""
    from panto.identification.estimation.base import fit_percent
    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose

    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="panto-benchmark-", dir=folder) as root:
        train = blind_data(_record(case, case.train_seed, Path(root) / "train", duration, True))
        validation = blind_data(_record(case, case.validation_seed, Path(root) / "validate",
                                        duration, True))
        twin = validation if case.label == "none" else blind_data(
            _record(case, case.validation_seed, Path(root) / "twin", duration, False))
        twin_train = train if case.label == "none" else blind_data(
            _record(case, case.train_seed, Path(root) / "twin_train", duration, False))
    fit_effect = {o: float(fit_percent(validation.outputs[:, j], twin.outputs[:, j]))
                  if case.label != "none" else 100.0
                  for j, o in enumerate(validation.output_names)}
    signal_cost = max(100.0 - f for f in fit_effect.values())
    fit_clean = clean_fit(structure, twin_train, twin)
    spread = {o: float(np.nanstd(validation.outputs[:, j]))
              for j, o in enumerate(validation.output_names)}
    try:
        result = diagnose(train, validation, structure=structure,
                          options=diagnose_options or DiagnosisOptions())
    except Exception as error:  # a failed case is scored as such, the benchmark goes on
        return CaseOutcome(case, "error", (), "error", signal_cost, {}, {}, fit_effect, math.nan,
                           time.perf_counter() - started, f"{type(error).__name__}: {error}",
                           spread, signal_cost=signal_cost, fit_clean=fit_clean)
    predicted = result.effects[0] if result.verdict == "effect" else result.verdict
    cost = 0.0 if case.label == "none" else max(
        0.0, max(fit_clean[o] - result.fit_before[o] for o in fit_clean))
    return CaseOutcome(case, result.verdict, tuple(result.effects), predicted, cost,
                       dict(result.fit_before), dict(result.fit_after), fit_effect,
                       gap_closed(result.fit_before, result.fit_after, fit_clean),
                       time.perf_counter() - started, "", spread, signal_cost=signal_cost,
                       fit_clean=fit_clean)


def clean_fit(structure: str, train: Any, validation: Any) -> dict[str, float]:
    """Validation fit [%] per output of the nominal fitted on effect-free twin runs.

    What the nominal reaches when the effect is absent (noise and the nominal's own limits only):
    the reference for the effect's *cost to the model* and for the gap closed (module notes).
    """
    from panto.identification.estimation.base import fit_percent
    from panto.identification.diagnosis.pipeline import fit_nominal
    from panto.identification.diagnosis.support import build_structure

    nominal, free = build_structure(structure, train, {})
    result = fit_nominal(nominal, free, train, max_evaluations=400)
    simulated = nominal.simulate(result.parameters, validation)
    return {o: float(fit_percent(validation.outputs[:, j], simulated[:, j]))
            for j, o in enumerate(validation.output_names)}


def gap_closed(fit_before: Mapping[str, float], fit_after: Mapping[str, float],
               fit_clean: Mapping[str, float]) -> float:
    """Share of the gap to the effect-free nominal removed (module notes); NaN without a gap.

    ``sum_o [(1 - f_before)^2 - (1 - f_after)^2] / sum_o [(1 - f_before)^2 - (1 - f_clean)^2]``
    with fits as fractions; 1 means the augmented model predicts as well as the nominal does
    when the effect is absent.
    """
    gap = sum((1 - fit_before[o] / 100) ** 2 - (1 - fit_clean[o] / 100) ** 2 for o in fit_clean)
    if not gap > 0:
        return math.nan
    removed = sum((1 - fit_before[o] / 100) ** 2 - (1 - fit_after[o] / 100) ** 2
                  for o in fit_clean)
    return float(removed / gap)


def blind_data(dataset: Any, *, rate: float = 50.0, skip: float = 0.0):
    """The rig mapping of a dataset with its truth metadata removed (what the diagnosis sees).

    `skip` [s] drops the start of the record. The default keeps it: the bed's runs start at rest,
    where the structures' free runs start too (static equilibrium with the first input sample).
    Dropping a moving start made a 6.7 N rms transient in the first second of a clean record
    (the diagnosis also leaves the nominal's settling time out of its gap tests, for records that
    do not start at rest)."""
    from panto.identification.data.datasets import pantograph_data

    dataset = dataclasses.replace(dataset, metadata=dataclasses.replace(dataset.metadata,
                                                                        truth={}))
    data = pantograph_data(dataset, rate=rate)
    return data.segment(skip, math.inf)


def _record(case: BenchmarkCase, seed: int, folder: Path, duration: float, with_effect: bool):
    """One virtual-test-bed run of the case (with or without its effect), post-processed."""
    from panto.build_fmu.project import project_fmu
    from panto.rig.dataset import read_dataset
    from panto.rig.imperfections import RigImperfections
    from panto.rig.virtual import run_virtual_profile

    bed = {k: v for k, v in case.settings.items() if k in
           {f.name for f in dataclasses.fields(RigImperfections)}}
    imperfections = dataclasses.replace(RigImperfections.none(), force_noise=1.0,
                                        laser_noise=1.5e-3, **(bed if with_effect else {}))
    run_virtual_profile(_profile(case, seed, duration), fmu_path=project_fmu("Pantograph"),
                        folder=folder, imperfections=imperfections, seed=seed % 100000)
    dataset = read_dataset(folder)
    if with_effect and case.kind == "outside":
        dataset = _post_process(dataset, case.settings)
    return dataset


def _profile(case: BenchmarkCase, seed: int, duration: float):
    from panto import rig as rig_package
    from panto.rig.profiles import load_profile

    base = load_profile(Path(rig_package.__file__).parent / "profiles" / "aprbs_training.json")
    conditioning = dataclasses.replace(base.conditioning, filter_cutoff=1.0)
    profile = dataclasses.replace(base, duration=float(duration), seed=base.seed + seed % 100000,
                                  conditioning=conditioning)
    if case.fast_profile:  # large, fast motor steps: the head cannot follow the falling bar
        motor = profile.motor
        signals = tuple(dataclasses.replace(s, std=0.05, hold_min=0.3, hold_max=1.0)
                        for s in motor.signals)
        profile = dataclasses.replace(
            profile, motor=dataclasses.replace(motor, signals=signals),
            conditioning=dataclasses.replace(base.conditioning, filter_cutoff=8.0))
    return profile


def _post_process(dataset: Any, settings: Mapping[str, Any]):
    """Out-of-library effects on the recorded force (module notes)."""
    from panto.identification.diagnosis.effects import play_operator

    force = np.asarray(dataset["force"], float)
    t = np.asarray(dataset.time, float)
    if "hysteresis_share" in settings:
        width = settings["hysteresis_width"] * float(np.std(force))
        force = force + settings["hysteresis_share"] * (play_operator(force, width) - force)
    if "gain_drift" in settings:
        span = max(t[-1] - t[0], 1e-9)
        force = force * (1.0 + settings["gain_drift"] * ((t - t[0]) / span - 0.5))
    return dataclasses.replace(dataset, channels={**dict(dataset.channels), "force": force})


# --- the whole benchmark --------------------------------------------------------------------

def run_diagnosis_benchmark(cases: int | Sequence[BenchmarkCase], seed: int = 0, *,
                            executor: Executor | None = None, progress: Progress | None = None,
                            duration: float = 25.0, structure: str = "physical-linear",
                            workers: int = 2,
                            diagnose_options: DiagnosisOptions | None = None
                            ) -> BenchmarkResult:
    """Draw (or take) the cases, run them through `executor` (a process pool of `workers` by
    default) and score them (module notes)."""
    say = progress or (lambda line: None)
    drawn = draw_cases(cases, seed) if isinstance(cases, int) else tuple(cases)
    say(f"diagnosis benchmark: {len(drawn)} cases, {duration:g} s runs, nominal {structure}")
    own = executor is None
    pool = ProcessPoolExecutor(max_workers=workers) if own else executor
    started = time.perf_counter()
    try:
        futures = [pool.submit(run_case, c, duration=duration, structure=structure,
                               diagnose_options=diagnose_options) for c in drawn]
        outcomes = []
        for case, future in zip(drawn, futures):
            outcome = future.result()
            outcomes.append(outcome)
            say(f"  case {case.index + 1}/{len(drawn)}: hidden {case.label} "
                f"(magnitude {case.magnitude:.3g}, cost {outcome.cost:.1f} points) -> "
                f"{outcome.predicted}" + (f" [{outcome.error}]" if outcome.error else ""))
    finally:
        if own:
            pool.shutdown()
    scores = score_outcomes(outcomes)
    scores["wall_time_s"] = time.perf_counter() - started
    say("diagnosis benchmark: " + describe_scores(scores))
    return BenchmarkResult(tuple(outcomes), scores, confusion_matrix(outcomes),
                           {"cases": len(drawn), "seed": seed, "duration_s": duration,
                            "structure": structure, "strong_fit_points": STRONG})


def confusion_matrix(outcomes: Sequence[CaseOutcome]) -> dict[str, dict[str, int]]:
    """Counts per true label (rows) and predicted label (columns)."""
    matrix: dict[str, dict[str, int]] = {}
    for o in outcomes:
        row = matrix.setdefault(o.case.label, {})
        row[o.predicted] = row.get(o.predicted, 0) + 1
    return matrix


def _rate(hits: int, total: int) -> float:
    return hits / total if total else math.nan


def score_outcomes(outcomes: Sequence[CaseOutcome]) -> dict[str, Any]:
    """The scores of the module notes, with their case counts."""
    library = [o for o in outcomes if o.case.kind == "library"]
    strong = [o for o in library if o.cost >= STRONG]
    correct = [o for o in strong if o.predicted == o.case.label]
    none = [o for o in outcomes if o.case.kind == "none"]
    outside = [o for o in outcomes if o.case.kind == "outside"]
    closed = [o.gap_closed for o in correct if math.isfinite(o.gap_closed)]
    return {
        "cases": len(outcomes), "library_cases": len(library), "strong_cases": len(strong),
        "top1_accuracy": _rate(len(correct), len(strong)),
        "top1_accuracy_all_library": _rate(sum(o.predicted == o.case.label for o in library),
                                           len(library)),
        "none_cases": len(none),
        "false_alarm_rate": _rate(sum(o.verdict == "effect" for o in none), len(none)),
        "none_unexplained_rate": _rate(sum(o.verdict == "unexplained" for o in none), len(none)),
        "none_recognised_rate": _rate(sum(o.verdict == "none" for o in none), len(none)),
        "outside_cases": len(outside),
        "unexplained_rate_outside": _rate(sum(o.verdict == "unexplained" for o in outside),
                                          len(outside)),
        "gap_closed_median": float(np.median(closed)) if closed else math.nan,
        "gap_closed_mean": float(np.mean(closed)) if closed else math.nan,
        "errors": sum(bool(o.error) for o in outcomes),
        "goals": {"top1_accuracy": 0.9, "false_alarm_rate": 0.05,
                  "unexplained_rate_outside": 0.8, "gap_closed_median": 0.8},
    }


def describe_scores(scores: Mapping[str, Any]) -> str:
    """One line: the four scores against their goals."""
    def pct(x: float) -> str:
        return "n/a" if not math.isfinite(x) else f"{100 * x:.0f} %"

    return (f"top-1 {pct(scores['top1_accuracy'])} of {scores['strong_cases']} strong library "
            f"cases (goal >= 90 %); false alarms {pct(scores['false_alarm_rate'])} of "
            f"{scores['none_cases']} none cases (goal <= 5 %; unexplained "
            f"{pct(scores['none_unexplained_rate'])}); unexplained "
            f"{pct(scores['unexplained_rate_outside'])} of {scores['outside_cases']} "
            f"out-of-library cases (goal >= 80 %); gap closed median "
            f"{pct(scores['gap_closed_median'])} (goal >= 80 %)")


__all__ = ["BenchmarkCase", "CaseOutcome", "BenchmarkResult", "draw_cases", "run_case",
           "run_diagnosis_benchmark", "score_outcomes", "confusion_matrix", "gap_closed",
           "blind_data", "describe_scores", "LIBRARY_DRAW", "OUTSIDE_DRAW", "STRONG"]
