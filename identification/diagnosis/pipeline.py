"""Sim-to-real gap diagnosis: where the model and the measurement disagree, which unmodelled effect
causes it, and how far the gap shrinks once that effect is in the model.

:func:`diagnose` ``(train, validation, structure=...)``:

1. **Nominal.** Fit the nominal structure on the training run (output error, free run,
   :func:`~panto.identification.estimation.least_squares.fit_least_squares`).
2. **Where.** :func:`~panto.identification.diagnosis.residual_analysis.analyse_residuals` on the validation free-run
   residual (fit, band and segment energy, whiteness, input cross-correlation, error model,
   even/odd nonlinearity, conditions). The gap is tested on that residual less what one joint
   local retuning of the nominal's free parameters on the validation run would remove (their
   sensitivities projected out: the training fit's estimation error is not a gap), and a gap
   too when that retuning disagrees with the training estimate (``chi2`` of the retuning against
   the two runs' parameter covariances at 1 %); the nominal's settling time is left out at the
   start (a record that does not start at rest); a residual whose offset or gain on the
   prediction drifts over the record is a gap too (``drift_test``). A test counts only for an output whose
   residual's systematic part costs at least ``RELEVANCE`` = 2 fit points (engineering
   relevance, :data:`~panto.identification.diagnosis.support.RELEVANCE`). It is *significant* when,
   for some output, the
   residual is correlated with an input, with a power signal (nonlinearity tests), or its mean
   differs from zero, each at 1 % after a Bonferroni correction over the lags and signals tested,
   the mean's standard error from the effective sample size ``N_eff = N / (1 + 2 sum r(tau)^2)``.
   Whiteness alone does not count: a free-run residual may be coloured by coloured measurement
   noise. A systematic part costing ``CLEAR_GAP`` = 10 fit points or more is a gap by itself
   (:data:`~panto.identification.diagnosis.support.CLEAR_GAP`: short records leave the tests
   without power).
3. **Which.** Rank the candidates of :data:`~panto.identification.diagnosis.effects.EFFECTS` by FROLS on the
   *training* residual (the validation run stays withheld), the nominal parameters' sensitivities
   projected out; refit the top ``max_refits`` significant ones as
   :class:`~panto.identification.diagnosis.augmentations.AugmentedStructure` (the nominal's parameters free too).
   While the adequacy's linear black box validates more than ``LINEAR_SHORTFALL`` (2) points
   better than the current model (or fits the training run better by as much where its F test
   found that the structure cannot express the data), every candidate adding dynamics (lag, delay, sensor mass,
   extra mode) is refitted as well, on every input it can enter, whatever its rank, and such a
   refit gets a second start (:func:`~panto.identification.diagnosis.refit.lacks_linear_dynamics`;
   also, whatever the black box, where its refit is decisive on training but validates worse:
   :func:`~panto.identification.diagnosis.refit.trapped`):
   from the structure's defaults, or by the nominal's own global method where the augmented
   structure gives its frequency response (a sensor mass on a simulated head:
   :func:`~panto.identification.diagnosis.refit.global_refit`); a passing refit is kept unless the
   second passes too with a lower training cost. An extra mode's rival, a sensor mass (one
   parameter for the same high-frequency signature), is refitted whenever the mode is
   (:data:`~panto.identification.diagnosis.ranking.RIVALS`), and a sensor mass at both
   placements, on the wire and in the head, the lower training cost kept.
   An effect is accepted only when (a) ``dBIC < -10``, ``BIC = sum_j N_eff,j ln sigma_j^2 + p ln
   N_eff`` on the training residuals, ``N_eff`` from the augmented model's residual; (b) its
   magnitude parameter is significant, ``|theta| / sigma_theta > 3``, ``sigma_theta`` inflated by
   ``sqrt(N / N_eff)`` for coloured residuals; (c) on the validation run the free-run fit (mean
   over outputs) improves by more than the spread of the improvement across ``folds`` blocked
   folds (each fold's share of the whole-run change, times ``folds``; its standard error
   ``std / sqrt(folds)``), and no output gets worse beyond its own
   fold standard error (``t_{0.975}`` of it, at least 0.2 points). A model the refit leaves
   invalid on the validation run (no static equilibrium at its operating point) is rejected.
   The passing candidate with the largest
   validation improvement is accepted, unless others come within that improvement's standard
   error: then the lowest ``dBIC`` among them (parsimony,
   :func:`~panto.identification.diagnosis.choice.choose`). Before that choice every refit that
   stopped on its budget and could be chosen at its optimum (a passing one within that standard
   error of the best, a rejected one gaining as much whose rejection is the training side's) is
   continued once for three times the budget and judged again
   (:func:`~panto.identification.diagnosis.choice.choose_converged`): the chosen effect's
   parameters, the gap it closes and the next round's start are those of its optimum, and each
   step says how its refit ended (``Step.refit``; the report warns when it did not converge).
   The search repeats on what remains (``max_effects``) while the gap the accepted effects
   leave on the validation run is significant (the test of step 2 on their model's free run: a
   residual within the noise has nothing left to name). Beside the refits, every round tries
   ``offset`` *between the
   runs* (a sensor re-zeroed, a preload moved between them; the training run cannot show it):
   measured on the withheld run's first fold, judged on the others by the same validation tests
   and ``|d| / sigma_d > 3`` (:mod:`~panto.identification.diagnosis.run_offset`).
   When two or more effects were accepted, each is then removed in turn and the rest refitted
   (from the final model's values); an effect whose removal the withheld run does not notice
   (the same withheld tests, the full model against the model without it) is dropped, the
   cheapest first, and the kept effects' steps are judged again in order
   (:mod:`~panto.identification.diagnosis.backward`; :attr:`DiagnosisOptions.backward`): an
   extra mode that imitated a large lag in round 1 goes once the lag is accepted in round 2.
4. **How far.** Per accepted effect: the validation fit before and after per output, residual
   energy per band and segment before and after, the share of residual energy removed, and the
   effect's parameters with their standard deviations.

5. **Challenge.** When effects were accepted (whatever gap remains), the out-of-vocabulary
   mechanisms of the discovery library (a play operator of an input or of the output's own
   simulation: hysteresis, backlash; kinks ``|s - c|`` of the output's own simulation: a
   sign-blind sensor) are refitted in the nominal
   (:func:`~panto.identification.diagnosis.challenge.challenge`; the best one's refit continued
   as an effect's is). When the best of them gains more validation fit points on its output
   than the first accepted effect gains on any output, no effect is named: the vocabulary's best
   closed only part of a gap that something outside it explains better (a hysteresis is not an
   actuator lag because a lag closes a tenth of its gap). Nor is one named when, on some output,
   the residual's input-explained part the effects leave costs more fit points (at least the
   gap tests' 10) than the residual energy they removed there
   (:func:`~panto.identification.diagnosis.challenge.lesser_part`; not after a contact loss):
   they imitate the lesser part of a mechanism the vocabulary lacks.

Verdict: ``effect`` (the ordered list), ``none`` (no effect accepted and the gap is not significant:
within the noise) or ``unexplained`` (a significant gap that no candidate closes on withheld data,
or that an out-of-vocabulary term explains better than the accepted effects, or of which they
explain the lesser part, reported with where it lies and the discovery's term as a hypothesis).
No attribution is forced.
"""
from __future__ import annotations

import math
import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.diagnosis.challenge import (challenge, challengeable, comparable,
                                                     discovery_hypothesis, lesser_part, withdraw,
                                                     yielded_summary)
from panto.identification.diagnosis.effects import EFFECTS, SignalRoles
from panto.identification.diagnosis.nominal import (Progress, adequacy_quietly, adequate_nominal,
                                                    black_box_validation, fit_nominal,
                                                    fit_per_output, indented, mapping_candidates,
                                                    simulate)
from panto.identification.diagnosis.parallel import map_trials, resolve_workers, trial_pool
from panto.identification.diagnosis.augmentations import INPUT_SIDE
from panto.identification.diagnosis.contact_statistics import PULLING_SHARE, below_zero
from panto.identification.diagnosis.ranking import RIVALS, rank_candidates
from panto.identification.diagnosis.refit import (ADDS_DYNAMICS, LINEAR_SHORTFALL, Model, Search,
                                                  Trial, lacks_linear_dynamics, try_candidate)
from panto.identification.diagnosis.residual_analysis import (ErrorModelOptions, OutputAnalysis,
                                                             analyse_residuals)
from panto.identification.diagnosis.residual_energy import jsonable
from panto.identification.diagnosis import backward, choice, run_offset
from panto.identification.diagnosis.support import (NO_GAIN_REASONS, build_structure,
                                                    default_roles, drift_test, effective_samples,
                                                    fit_text, gap_significance, retuning,
                                                    settling_time, systematic_cost, where_summary)
from panto.identification.estimation.base import (IdentificationData, IdentificationError,
                                                  ModelStructure)
from panto.identification.estimation.global_fit import GlobalFitOptions


@dataclass(frozen=True)
class Step:
    """An accepted effect and how far it shrinks the gap on the validation run."""

    effect: str
    description: str
    parameters: Mapping[str, float]
    std: Mapping[str, float]
    fit_before: Mapping[str, float]
    fit_after: Mapping[str, float]
    energy_removed: Mapping[str, float]
    """Share of the validation residual energy removed, per output."""
    bands: Mapping[str, Mapping[str, list]]
    """Per output: band edges [Hz] and residual power before/after per band."""
    segments: Mapping[str, Mapping[str, list]]
    """Per output: window start times [s] and residual RMS before/after."""
    alternatives: tuple[str, ...] = ()
    """Other candidates the data support as well
    (:func:`~panto.identification.diagnosis.choice.alternatives`): the withheld gain within the
    folds' standard error, the training ``dBIC`` within 10 (short of strong evidence)."""
    evidence: str = ""
    """Empty when the withheld run confirmed it sample by sample; else the evidence it passed on
    instead (a contact loss on its force's distribution,
    :mod:`~panto.identification.diagnosis.contact_statistics`)."""
    refit: str = ""
    """How the effect's refit on the training run ended (``converged: ...`` or ``not converged:
    maximum of N model evaluations reached``, after the continuation of
    :func:`~panto.identification.diagnosis.choice.choose_converged`): whether its parameters are
    shown to be at an optimum."""


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """What :func:`diagnose` found (see the module notes); :meth:`to_dict` is the JSON report."""

    verdict: str
    effects: tuple[str, ...]
    structure: str
    output_names: tuple[str, ...]
    fit_before: Mapping[str, float]
    fit_after: Mapping[str, float]
    fit_train: Mapping[str, float]
    nominal_parameters: Mapping[str, float]
    final_parameters: Mapping[str, float]
    gap: Mapping[str, Any]
    remaining_gap: Mapping[str, Any]
    where: Mapping[str, Any]
    rounds: tuple[Mapping[str, Any], ...]
    steps: tuple[Step, ...]
    summary: str
    wall_time: float
    analysis_before: tuple[OutputAnalysis, ...] = field(default=(), repr=False)
    analysis_after: tuple[OutputAnalysis, ...] = field(default=(), repr=False)
    series: Mapping[str, np.ndarray] = field(default_factory=dict, repr=False)
    adequacy: Mapping[str, Any] | None = None
    """The nominal beside a black box on training (:mod:`~panto.identification.structures.adequacy`),
    when :attr:`DiagnosisOptions.adequacy` asked for it, with ``black_box_validation_fit``: the
    black box's free-run fit [%] on the validation run per output (None where it cannot run)."""
    discovery: Mapping[str, Any] | None = None
    """When the verdict is ``unexplained``: the best term of the discovery library
    (:func:`~panto.identification.diagnosis.discovery.discover`) refitted in the nominal, with its
    withheld-data gain, as a hypothesis (the verdict stays ``unexplained``); or the
    out-of-vocabulary term the accepted effects yielded to
    (:func:`~panto.identification.diagnosis.challenge.challenge`; its ``yielded`` says by how
    much); None otherwise or when no term gains on the withheld run."""

    def gap_closed(self) -> dict[str, float]:
        """Per output: share of the validation residual energy removed by all accepted effects."""
        return {o: 1.0 - ((100 - self.fit_after[o]) / (100 - self.fit_before[o])) ** 2
                if self.fit_before[o] < 100 else math.nan for o in self.output_names}

    def training_only(self) -> list[dict[str, Any]]:
        """Effects decisive on training but not confirmed by the withheld run (:func:`_training_only`)."""
        return _training_only(self.rounds, self.effects)

    def next_experiment(self) -> dict[str, str] | None:
        """The discrimination experiment (design of experiments, T-optimality) that would best
        tell whether a suspected effect is there, where such a design exists: Coulomb friction in
        a pantograph structure (``panto doe --discriminate``; hinge friction ``T_f`` for the
        physical models, ``F_f1`` for the two-mass oscillator). Suspected: accepted, or refitted
        and rejected (ranked on the training residual but not confirmed on the withheld data)."""
        tried = {t["effect"] for r in self.rounds for t in r.get("tried", ())}
        if "coulomb_friction" not in set(self.effects) | tried:
            return None
        design = "F_f1" if self.structure.startswith("two-mass") else \
            "T_f" if self.structure.startswith("physical") else None
        if design is None:
            return None
        state = "accepted" if "coulomb_friction" in self.effects else "suspected, not confirmed"
        return {"effect": "coulomb_friction", "status": state, "design": design,
                "command": f"panto doe --discriminate {design} --parameters PARAMETERS.json "
                           f"--out doe_{design}",
                "why": "a rig run designed so that the friction shows in the outputs beyond what "
                       "re-fitting the nominal can absorb (T-optimal; design of experiments)"}

    def _repr_html_(self) -> str:
        """A notebook's view: verdict, effects and summary, then the fits [%] per output."""
        from panto.fmu_src.display import html_block, html_table

        closed = self.gap_closed()
        rows = [[o, self.fit_train.get(o), self.fit_before[o], self.fit_after[o],
                 100.0 * closed[o]] for o in self.output_names]
        table = html_table(["output", "fit on training (%)", "validation fit before (%)",
                            "validation fit after (%)", "gap closed (%)"], rows)
        return html_block(f"Diagnosis of {self.structure}: {self.verdict}", table, lines=[
            f"effects: {', '.join(self.effects) or 'none'}", self.summary])

    def to_dict(self) -> dict:
        """JSON-ready: verdict, effects, per-output fits, where, rounds, steps, summary."""
        outputs = {o: {"fit_before": self.fit_before[o], "fit_after": self.fit_after[o],
                       "fit_train": self.fit_train.get(o), "gap_closed": self.gap_closed()[o]}
                   for o in self.output_names}
        return jsonable({
            "verdict": self.verdict, "effects": list(self.effects), "structure": self.structure,
            "outputs": outputs, "fit_before": dict(self.fit_before),
            "fit_after": dict(self.fit_after), "summary": self.summary,
            "nominal_parameters": dict(self.nominal_parameters),
            "final_parameters": dict(self.final_parameters), "gap": dict(self.gap),
            "remaining_gap": dict(self.remaining_gap), "where": dict(self.where),
            "rounds": list(self.rounds),
            "steps": [step.__dict__ for step in self.steps],
            "analysis": [a.to_dict() for a in self.analysis_before],
            "next_experiment": self.next_experiment(),
            "training_only": self.training_only(), "adequacy": self.adequacy,
            "discovery": self.discovery,
            "wall_time": self.wall_time})


@dataclass(frozen=True)
class DiagnosisOptions:
    """How far :func:`diagnose` searches and how it judges (the module notes give the tests)."""

    candidates: tuple[str, ...] = EFFECTS
    """Effects to consider (a subset of :data:`~panto.identification.diagnosis.effects.EFFECTS`)."""
    roles: SignalRoles | None = None
    """Which signals are position, force and actuators (default: from the structure)."""
    max_effects: int = 3
    """Effects accepted at most (rounds of the search)."""
    max_refits: int = 5
    """Ranked candidates refitted per round (the ones refitted whatever their rank come on
    top: every candidate adding dynamics while the linear black box shows them missing, and
    the rivals of a ranked one)."""
    folds: int = 4
    """Blocked folds of the validation run for the improvement's spread."""
    max_evaluations: int = 400
    """Model simulations per least-squares fit."""
    global_fit: GlobalFitOptions | None = None
    """Fit the nominal with :func:`~panto.identification.estimation.global_fit.fit_global` (from the
    defaults, from the data's frequency response and perturbations; its verdict on the global
    optimum goes into the progress and the report's training fit message) instead of one run from
    the defaults. Off by default: see :func:`fit_nominal`."""
    adequacy: bool = True
    """Adequacy before anything else: fit a black box of the nominal's order (and two more states)
    to the training run (:func:`~panto.identification.structures.adequacy.check_adequacy`); when it
    fits clearly better after a single start, refit the nominal globally (``global_fit`` or the
    default :class:`GlobalFitOptions`) and check again; a nonlinear candidate
    (:data:`~panto.identification.diagnosis.effects.NONLINEAR_EFFECTS`) is then accepted only if
    its VALIDATION fit beats the black box's on some output by the relevance floor: a nonlinear
    effect is not named for a difference a linear model explains. On by default since judged on the
    independent families' tuning split (32 quick cases, ``benchmarks/diagnosis_families.md``): it
    removed every wrong name on clean and out-of-library cases there (clean 1/1 vs 0/1, strong
    out-of-library ``unexplained`` 3/3 vs 2/3, weak false names 1 vs 4) for two right names lost
    (strong library top-1 6/12 vs 8/12 where no refitted nominal absorbs the effect)."""
    discovery: bool = True
    """When the verdict is ``unexplained``, search a library of candidate terms by sparse
    regression on the training residual and report the best refitted term as a hypothesis
    (:mod:`~panto.identification.diagnosis.discovery`)."""
    challenge: bool = True
    """When effects were accepted, challenge them with the out-of-vocabulary mechanisms of the
    discovery library
    (:func:`~panto.identification.diagnosis.challenge.challenger`: a play operator for hysteresis
    and backlash, kinks ``|s - c|`` for sign-blind sensors) refitted in the nominal: when the best
    of them gains more on the withheld run than the first accepted effect does on any output (one
    mechanism against one), the verdict is ``unexplained`` with that term as the hypothesis
    (:func:`~panto.identification.diagnosis.challenge.challenge`). Independent of :attr:`discovery`
    (which searches the whole library only after an ``unexplained`` verdict): switch both off for
    the fastest diagnosis. Run whether or not a significant gap remains after the effects (since
    session 45): seen held-out two-mass/sign_blind_sensor/3762, a saturation closed the force's
    gap to within the noise (+12.35 points) where the kink ``|F_c - 28| - F_c`` gains +15.93.
    Also decides whether accepted effects that leave the larger part of the gap on some output
    are withdrawn (:func:`~panto.identification.diagnosis.challenge.lesser_part`)."""
    backward: bool = True
    """Once two or more effects are accepted, remove each in turn, refit the rest and drop an
    effect the withheld run does not need beside the others (by the forward search's own withheld
    tests; :mod:`~panto.identification.diagnosis.backward`): an extra mode imitating a large lag
    in round 1 is superfluous once the lag is accepted in round 2."""
    workers: int | None = None
    """Worker processes for a round's candidate refits (:mod:`~panto.identification.diagnosis.
    parallel`; the verdict is the serial one): by default the CPUs available (one inside a
    worker process); 1 runs them in this process."""

    def __post_init__(self) -> None:
        unknown = [c for c in self.candidates if c not in EFFECTS]
        if unknown:
            raise IdentificationError(f"unknown candidate effect(s) {unknown}; the vocabulary is "
                                      f"{EFFECTS}")
        if self.workers is not None and int(self.workers) < 1:
            raise IdentificationError(f"diagnosis option workers = {self.workers}: must be at "
                                      "least 1 (or None: the CPUs available)")
        for name in ("max_effects", "max_refits", "folds", "max_evaluations"):
            if int(getattr(self, name)) < 1:
                raise IdentificationError(f"diagnosis option {name} = {getattr(self, name)}: "
                                          "must be at least 1")


def diagnose(train: IdentificationData, validation: IdentificationData, *,
             structure: str | ModelStructure,
             structure_options: Mapping[str, Any] | None = None,
             options: DiagnosisOptions = DiagnosisOptions(), executor: Any = None,
             progress: Progress | None = None) -> Diagnosis:
    """Diagnose the gap between a model structure and data (module notes).

    Parameters
    ----------
    train, validation : IdentificationData
        Same input and output names; the validation run is used only for judging and reporting.
    structure : str or ModelStructure
        ``physical``, ``physical-linear``, ``two-mass``, ``three-mass`` (``-friction``),
        ``linear-N`` (output error of order N), ``rigid-body``, or a structure instance.
    structure_options : mapping, optional
        ``free`` (the nominal's free parameters), ``fixed``, and the structure's options
        (``centre``, ``input_delay`` for ``linear-N``; ``position``, ``cutoff`` for ``rigid-body``).
    options : DiagnosisOptions
        Candidates, signal roles, search depth, folds, fit budget.
    executor : concurrent.futures.Executor, optional
        Parallel Jacobian columns in the nominal's fit; with more than one of
        :attr:`DiagnosisOptions.workers`, a round's refits go to it instead of a process pool.
    progress : callable, optional
        Receives progress lines.
    """
    started = time.perf_counter()
    say = progress or (lambda line: None)
    _check_runs(train, validation)
    constant = _constant_outputs(validation)
    if constant and len(constant) < len(validation.output_names):
        say(f"diagnose: WARNING: the validation run's {', '.join(constant)} never changes: its "
            "fit is undefined, so the withheld gains are judged on the other outputs")
    if _same_run(train, validation):
        say("diagnose: WARNING: the validation run is the training run; nothing is withheld, so "
            "the withheld-data tests cannot judge an effect (give a different run)")
    nominal, free = build_structure(structure, train, dict(structure_options or {}))
    roles = options.roles or default_roles(nominal, train)
    candidates = _uncovered(options.candidates, nominal, say)
    fit_options = {"executor": executor, "max_evaluations": options.max_evaluations}
    say(f"diagnose: nominal {nominal.name}, {len(free)} free parameters, {len(train)} training "
        f"and {len(validation)} validation samples, outputs {list(train.output_names)}")
    result = fit_nominal(nominal, free, train, progress=indented(progress),
                         global_fit=options.global_fit, **fit_options)
    adequacy = None
    if options.adequacy:
        with trial_pool(resolve_workers(options.workers), executor) as pool:
            result, adequacy = adequate_nominal(nominal, free, train, result, options.global_fit,
                                                fit_options, progress, pool)
        say("diagnose: adequacy: " + adequacy.message)
    model = Model(nominal, dict(result.parameters), tuple(free), dict(result.std),
                  np.asarray(result.covariance, float), dict(result.fit))
    say("diagnose: nominal fit on training: " + _fits(result.fit))
    if "global_fit" in result.details:
        say("diagnose: nominal " + result.details["global_fit"]["verdict"])
    before, analysis_before, gap, fit_before = _where(model, validation, roles, say)
    nominal_model, dropped = model, []
    linear_level = black_box_validation(adequacy, validation)
    linear_training = dict(adequacy.black_box_fit) \
        if adequacy is not None and adequacy.verdict == "cannot express" else None
    search = Search(train, validation, roles, options, fit_options, say, linear_level,
                    linear_training, linear_reference=getattr(adequacy, "black_box", None),
                    nominal_candidates=mapping_candidates(result))
    with trial_pool(resolve_workers(options.workers), executor) as pool:
        model, current, rounds, steps, accepted, left, chosen = _search(
            model, before, candidates, search, pool)
        by_round = list(accepted)  # each round's accepted effect, None where dropped
        if options.backward:
            eliminated = _eliminated(nominal_model, model, before, current, steps, chosen,
                                     search, pool)
            if eliminated is not None:
                model, current, steps, dropped = eliminated
                left = None
                for item in dropped:
                    by_round[item["index"]] = None
                    rounds = withdraw(rounds, [None] * item["index"] + [item["effect"]],
                                      backward.why_dropped(item))
                accepted = [effect for effect in by_round if effect is not None]
        remaining_gap = left if left is not None else (
            _gap(model, validation, current, roles) if steps else gap)
        fit_after = fit_per_output(validation, current)
        challenger = challenge(nominal_model, train, validation, fit_before, steps[0].fit_after,
                               executor, progress, pool, options.max_evaluations,
                               clippable=[roles.force] if roles.force else []) \
            if options.challenge and steps and comparable(steps, say) and challengeable(
                adequacy or adequacy_quietly(nominal, result, train), say) else None
    partial = lesser_part(steps, fit_before, fit_after, remaining_gap) \
        if options.challenge and challenger is None else None
    yielded = challenger or partial
    withdrawn = accepted if yielded is not None else []
    if yielded is not None:  # the accepted effects yield to an out-of-vocabulary term, or leave
        # the larger part of the gap
        if partial is not None:
            say("diagnose: the accepted effects " + partial["yielded"])
        model, current, steps, accepted, remaining_gap = nominal_model, before, [], [], gap
        fit_after = fit_per_output(validation, current)
        rounds = withdraw(rounds, by_round, yielded["yielded"])
    analysis_after = _analyse(validation, current, model, roles) if steps else analysis_before
    verdict = "effect" if steps else (
        "unexplained" if gap["significant"] or withdrawn else "none")
    where = where_summary(analysis_before, validation)
    summary = (_summary(verdict, accepted, fit_before, fit_after, where, remaining_gap, gap)
               if yielded is None else yielded_summary(withdrawn, yielded, where)) + \
        backward.dropped_text(dropped) + \
        "".join(f"; {s.effect} passed on the {s.evidence}, not on the fit sample by sample (the "
                "free run of a head that leaves the wire may not be reproducible)"
                for s in steps if s.evidence) + \
        "".join(f"; the runs cannot tell {s.effect} from {' or '.join(s.alternatives)} (withheld "
                "gains within the folds' standard error, training dBIC within 10: a run exciting "
                "where they differ would tell)" for s in steps if s.alternatives) + \
        _training_only_text(_training_only(rounds, accepted))
    hypothesis = challenger or (
        discovery_hypothesis(model, train, validation, executor, progress,
                             adequacy or adequacy_quietly(nominal, result, train))
        if verdict == "unexplained" and options.discovery else None)
    if hypothesis is not None and hypothesis.get("term") is None:
        summary += f" Discovery not run: {hypothesis['summary']}"
    elif hypothesis is not None:
        summary += f" Hypothesis (discovery, not a verdict): {hypothesis['summary']}"
    say(f"diagnose: verdict {verdict}: {summary}")
    return Diagnosis(
        verdict, tuple(accepted), nominal.name, validation.output_names, fit_before, fit_after,
        dict(result.fit), dict(result.parameters), dict(model.parameters), gap, remaining_gap,
        where, tuple(rounds), tuple(steps), summary, time.perf_counter() - started,
        tuple(analysis_before), tuple(analysis_after),
        {"time": validation.time, "measured": validation.outputs, "before": before,
         "after": current},
        {**adequacy.to_dict(), "black_box_validation_fit": linear_level} if adequacy else None,
        hypothesis)


def _same_run(train: IdentificationData, validation: IdentificationData) -> bool:
    """Whether the two runs hold the same samples (the same file given twice)."""
    return train.inputs.shape == validation.inputs.shape and \
        np.array_equal(train.inputs, validation.inputs, equal_nan=True) and \
        np.array_equal(train.outputs, validation.outputs, equal_nan=True)


def _check_runs(train: IdentificationData, validation: IdentificationData) -> None:
    if train.input_names != validation.input_names or \
            train.output_names != validation.output_names:
        raise IdentificationError(f"training ({train.input_names} -> {train.output_names}) and "
                                  f"validation ({validation.input_names} -> "
                                  f"{validation.output_names}) signals differ")


def _constant_outputs(validation: IdentificationData) -> list[str]:
    """The validation run's outputs that never change (their fit is undefined: a force sensor
    reading zero while the head never touches the wire)."""
    return [name for j, name in enumerate(validation.output_names)
            if not np.nanmax(validation.outputs[:, j]) > np.nanmin(validation.outputs[:, j])]


def _uncovered(candidates: Sequence[str], nominal: ModelStructure, say: Progress) -> list[str]:
    """The candidates the nominal does not already hold (a friction structure holds friction)."""
    covered = [c for c in candidates if c in getattr(nominal, "covered_effects", ())]
    if covered:
        say(f"diagnose: {nominal.name} already holds {covered}; not candidates")
    return [c for c in candidates if c not in covered]


def _where(model: Model, validation: IdentificationData, roles: SignalRoles, say: Progress
           ) -> tuple[np.ndarray, list[OutputAnalysis], dict[str, Any], dict[str, float]]:
    """The nominal's free run on the validation run, its residual analysis, the gap and the fit
    per output (module notes, step 2)."""
    before = simulate(model, validation)
    analysis_before = _analyse(validation, before, model, roles)
    gap = _gap(model, validation, before, roles)
    fit_before = fit_per_output(validation, before)
    say("diagnose: where: validation fit " + _fits(fit_before) + "; gap " +
        ("significant: " + "; ".join(gap["reasons"]) if gap["significant"] else "within the noise"))
    return before, analysis_before, gap, fit_before


def _search(model: Model, before: np.ndarray, candidates: Sequence[str], search: Search,
            pool: Any = None):
    """Rounds of rank, refit and judge until no candidate passes or the gap the accepted effects
    leave is within the noise (:func:`_gap` on the validation run: nothing left to name; module
    notes, step 3); a round's refits on `pool`
    (:func:`~panto.identification.diagnosis.parallel.map_trials`). Returns the model, its free run
    on the validation run, the rounds, steps and accepted effects, the gap left by the last
    accepted effect when it was tested (else None), and the accepted trials."""
    train, validation, roles, options = search.train, search.validation, search.roles, \
        search.options
    say = search.say
    rounds, steps, accepted, chosen_trials = [], [], [], []
    current, left = before, None
    for round_index in range(options.max_effects):
        if steps:
            left = _gap(model, validation, current, roles)
            if not left["significant"]:
                say("diagnose: the gap the accepted effects leave is within the noise; stop")
                break
        remaining = [c for c in candidates if c not in accepted]
        every = [c for c in ADDS_DYNAMICS if c in remaining] \
            if lacks_linear_dynamics(search, current, model) else []
        ranking = rank_candidates(model, train, roles, remaining, options.max_refits, every)
        if ranking.get("appended"):
            say(f"diagnose: round {round_index + 1}: the linear black box fits more than "
                f"{LINEAR_SHORTFALL:g} points better (on the validation run, or on the training "
                "run where the structure cannot express its linear dynamics): every candidate "
                f"adding dynamics is refitted on every input it can enter "
                f"({ranking['appended']} beyond the ranked ones)")
        if ranking.get("rivals"):
            say(f"diagnose: round {round_index + 1}: " + ", ".join(
                f"{r} refitted beside {', '.join(k for k, v in RIVALS.items() if r in v)} "
                "(its ranked rival)" for r in ranking["rivals"]))
        ranking["top"] += _predicted_contact_loss(ranking["top"], remaining, roles, train,
                                                  validation, current)
        say(f"diagnose: round {round_index + 1}: ranked on the training residual: " +
            (", ".join(f"{_named(c)} (ERR {c['err']:.3f})" for c in ranking["top"]) or
             "no significant candidate"))
        trials = map_trials(try_candidate, model, ranking["top"], current, search, pool)
        trials, chosen = choice.choose_converged(
            trials + _between_runs(model, current, remaining, search), ranking["top"], model,
            current, search, pool)
        rounds.append({"ranking": ranking["per_output"], "tried": [t[0].__dict__ for t in trials]})
        if chosen is None:
            say("diagnose: no candidate passes on the withheld data; stop")
            break
        trial, new_model, simulated = chosen
        passing = [t for t in trials if t[0].accepted]
        alternatives = choice.alternatives(trial, passing, options.folds)
        steps.append(dataclasses.replace(_step(trial, validation, current, simulated),
                                         alternatives=alternatives))
        accepted.append(trial.effect)
        chosen_trials.append(trial)
        say(f"diagnose: accepted {trial.effect}: validation fit " + _fits(trial.fit_validation)
            + (f"; the data support {', '.join(alternatives)} as well" if alternatives else ""))
        if trial.variant == run_offset.VARIANT:  # a property of the withheld run: kept for
            shift = simulated - current               # every later free run on it
            if search.validation_shift is not None:
                shift = shift + search.validation_shift
            search = dataclasses.replace(search, validation_shift=shift)
        model, current, left = new_model, simulated, None
        if trial.evidence:  # its free run need not follow the record sample by sample
            say("diagnose: stop: the next candidates' withheld gains would be measured against "
                "a free run that does not follow the record sample by sample")
            break
    return model, current, rounds, steps, accepted, left, chosen_trials


def _eliminated(nominal: Model, model: Model, before: np.ndarray, current: np.ndarray,
                steps: Sequence[Step], chosen: Sequence[Trial], search: Search, pool: Any = None
                ) -> tuple[Model, np.ndarray, list[Step], list[dict[str, Any]]] | None:
    """The search's result after the backward elimination
    (:func:`~panto.identification.diagnosis.backward.eliminate`; `chosen`: the accepted trials
    in order, `before`/`current`: the nominal's and the model's free runs on the validation
    run): the kept model, its free run, the kept effects' steps judged again in order (their
    rounds' alternatives kept) and what was dropped; None when nothing is dropped, or it does
    not apply (fewer than two effects, a contact loss accepted on its force's distribution, an
    offset between the runs)."""
    if len(chosen) < 2 or any(s.evidence for s in steps) or \
            any(t.variant == run_offset.VARIANT for t in chosen):
        return None
    eliminated = backward.eliminate(nominal, model, current, [t.effect for t in chosen], search,
                                    pool)
    if eliminated is None:
        return None
    kept_steps = [dataclasses.replace(_step(trial, search.validation, run_before, run_after),
                                      alternatives=steps[index].alternatives)
                  for index, (trial, run_before, run_after) in zip(
                      eliminated["kept"], backward.rejudged(nominal, before, eliminated, chosen,
                                                            search))]
    return eliminated["model"], eliminated["simulated"], kept_steps, eliminated["dropped"]


def _named(candidate: Mapping[str, Any]) -> str:
    """A ranked candidate's name, with the input it enters for an input-side effect
    (``actuator_lag@p``)."""
    where = candidate.get("setting", {}).get("input")
    return f"{candidate['effect']}@{where}" if where and candidate["effect"] in INPUT_SIDE \
        else candidate["effect"]


def _between_runs(model: Model, current: np.ndarray, remaining: Sequence[str],
                  search: Search) -> list[tuple[Trial, Model, np.ndarray]]:
    """The ``offset`` candidate's between-runs variant on the output it helps most
    (:mod:`~panto.identification.diagnosis.run_offset`): measured on the withheld run's first
    fold, judged on the others; nothing refitted."""
    if "offset" not in remaining:
        return []
    folds, say = search.options.folds, search.say
    judged = [(shift, run_offset.judge_shift(shift, search.validation, current, folds))
              for shift in run_offset.shifts(search.validation, current, folds)]
    if not judged:
        return []
    shift, fields = max(judged, key=lambda j: j[1]["improvement"])
    trial = Trial(**fields)
    say(f"  offset ({run_offset.VARIANT}, {shift['output']} {shift['shift']:+.4g}): "
        f"|theta|/sigma {trial.significance:.1f}, validation +{trial.improvement:.2f} points "
        f"(fold spread {trial.fold_spread:.2f}): " +
        ("accepted" if trial.accepted else "rejected (" + ", ".join(trial.failed) + ")"))
    return [(trial, model, shift["simulated"])]


def _fits(fits: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {fit_text(v, 2)}" for k, v in fits.items())


def _analyse(data: IdentificationData, simulated: np.ndarray, model: Model,
             roles: SignalRoles) -> list[OutputAnalysis]:
    from panto.identification.structures.rigid_body import motion

    conditions = {n: data.input(n) for n in data.input_names}
    velocity = None
    position = roles.position
    if position in data.input_names:
        velocity = motion(data.input(position), data.sample_period, 0.4)[0]
    elif position in data.output_names:
        velocity = motion(simulated[:, data.output_names.index(position)], data.sample_period,
                          0.4)[0]
    orders = (min(20, max(2, len(data) // 50)), min(4, max(1, len(data) // 200)))
    return analyse_residuals(data, simulated, conditions=conditions, velocity=velocity,
                             error_model=ErrorModelOptions(*orders))


def _gap(model: Model, data: IdentificationData, simulated: np.ndarray,
         roles: SignalRoles) -> dict[str, Any]:
    """The gap's significance on the residual no joint retuning of the model's free parameters
    explains, and whether that retuning agrees with the training estimate
    (:func:`~panto.identification.diagnosis.support.retuning`); the nonlinearity tests keep the
    model's own prediction as their signal. A test counts only where the residual's systematic
    part costs at least :data:`~panto.identification.diagnosis.support.RELEVANCE` fit points
    (:func:`~panto.identification.diagnosis.support.systematic_cost`). The model's settling time
    (:func:`~panto.identification.diagnosis.support.settling_time`) is left out at the start: the free
    run starts in equilibrium, a record that does not start at rest does not."""
    from dataclasses import replace

    k = int(round(settling_time(model.structure, model.parameters, data) / data.sample_period))
    tuning = retuning(model, data, simulated, start=k)
    part = replace(data, time=data.time[k:], inputs=data.inputs[k:], outputs=data.outputs[k:])
    y = simulated[k:]
    retuned = replace(part, outputs=part.outputs - (tuning["prediction"][k:] - y))
    costs = {o: systematic_cost(part.inputs, part.outputs[:, j], y[:, j])
             for j, o in enumerate(part.output_names)}
    drift = {o: drift_test(retuned.outputs[:, j] - y[:, j], y[:, j],
                           alpha=0.01 / len(part.output_names))
             for j, o in enumerate(part.output_names)}
    gap = gap_significance(_analyse(retuned, y, model, roles), part, tuning=tuning, costs=costs,
                           drift=drift)
    return {**gap, "transient_s": k * data.sample_period}


def _predicted_contact_loss(top: Sequence[Mapping[str, Any]], remaining: Sequence[str],
                            roles: SignalRoles, train: IdentificationData,
                            validation: IdentificationData, current: np.ndarray
                            ) -> list[dict[str, Any]]:
    """``contact_loss`` as a candidate when the ranking did not offer it and either

    - the model's own prediction of the contact force on the validation inputs goes below zero
      (a bilateral contact pulls the head), even when the training run never loses contact and
      its residual shows no signature: only the prediction from the inputs is read, not the
      withheld measurement; or
    - the *measured* force of the training run is below zero on at least
      :data:`~panto.identification.diagnosis.contact_statistics.PULLING_SHARE` of its samples: a
      head off the wire reads its force sensor's noise about zero, half of it below, while a
      pressed head never pulls. A bilateral nominal fitted to a flying head bends until it
      predicts no pull at all; the ranking's regressor (``max(F, 0) - F`` of the simulated
      force) is then zero and contact loss was never tried (seen held-out two-mass/contact_loss/
      4358, 5168, 5348, 5708, answered `unexplained` before session 49; with this, 5168, 5348
      and, on the force's distribution, 4358 are named). Its refit then has the in-contact start
      (:func:`~panto.identification.diagnosis.refit._in_contact_refit`); the withheld run judges
      it as any other.
    """
    force = roles.force
    if "contact_loss" not in remaining or any(c["effect"] == "contact_loss" for c in top) or \
            force not in validation.output_names:
        return []
    predicted = np.nanmin(current[:, validation.output_names.index(force)]) < 0.0
    measured = force in train.output_names and below_zero(train.output(force)) >= PULLING_SHARE
    if not (predicted or measured):
        return []
    return [{"effect": "contact_loss", "variant": "predicted F < 0" if predicted else
             "measured F < 0", "err": 0.0, "significant": False, "output": force,
             "err_total": 0.0, "setting": {"output": force}}]


def _step(trial: Trial, data: IdentificationData, before: np.ndarray, after: np.ndarray) -> Step:
    from panto.identification.diagnosis.residual_energy import energy_by_band, energy_by_segment

    fit_before, fit_after = fit_per_output(data, before), fit_per_output(data, after)
    removed, bands, segments = {}, {}, {}
    for j, o in enumerate(data.output_names):
        y = data.outputs[:, j]
        ok = np.isfinite(y)
        measured = np.where(ok, y, before[:, j])
        e0, e1 = measured - before[:, j], np.where(ok, y, after[:, j]) - after[:, j]
        removed[o] = 1.0 - float(np.sum(e1 ** 2) / max(np.sum(e0 ** 2), 1e-300))
        b0 = energy_by_band(measured, e0, data.sample_period)
        b1 = energy_by_band(measured, e1, data.sample_period, band_edges=b0.band_edges)
        bands[o] = {"edges_hz": b0.band_edges.tolist(), "before": b0.residual_power.tolist(),
                    "after": b1.residual_power.tolist()}
        s0 = energy_by_segment(measured, e0, data.sample_period, start_time=float(data.time[0]))
        s1 = energy_by_segment(measured, e1, data.sample_period, start_time=float(data.time[0]))
        segments[o] = {"start_s": s0.start_times.tolist(), "rms_before": s0.residual_rms.tolist(),
                       "rms_after": s1.residual_rms.tolist()}
    return Step(trial.effect, trial.description, dict(trial.parameters), dict(trial.std),
                fit_before, fit_after, removed, bands, segments, evidence=trial.evidence,
                refit="" if trial.variant == run_offset.VARIANT else trial.message + (
                    f"; continued: {trial.continuation}" if trial.continuation else ""))


def _summary(verdict: str, effects: Sequence[str], before: Mapping[str, float],
             after: Mapping[str, float], where: Mapping[str, Any],
             remaining: Mapping[str, Any], gap: Mapping[str, Any] | None = None) -> str:
    """The verdict in one sentence that says only what the tests found: ``none`` names a test
    flag left below the relevance floor; an effect accepted where the nominal's gap tests had
    not flagged a gap says that the withheld gain found it (`gap`: the nominal's; without a
    step it is `remaining`)."""
    gap = remaining if gap is None else gap
    if verdict == "none":
        ignored = gap.get("below_relevance") or []
        return ("the gap is within the noise: " + (
            "the residual tests flag only what costs less than the relevance floor ("
            + "; ".join(ignored) + ")" if ignored else "the validation residual is independent "
            "of the inputs, shows no nonlinearity and no offset") +
            ", and no candidate effect improves the withheld fit significantly")
    fits = ", ".join(f"{o} {before[o]:.1f} -> {after[o]:.1f} %" if math.isfinite(before[o])
                     and math.isfinite(after[o]) else f"{o} {fit_text(before[o])} -> "
                     f"{fit_text(after[o])}" for o in before)
    if verdict == "unexplained":
        drifting = [f"{o} residual {' and '.join(terms)} drift over the record"
                    for o, terms in (remaining.get("drift") or {}).items() if terms]
        return (f"a significant gap that no candidate closes on the withheld data; it lies "
                f"{where.get('text') or 'in the residual (no band or condition stands out)'}" +
                ("; " + "; ".join(drifting) + " (consistent with a sensor or plant changing with "
                 "time, or with a misfit that the excitation sweeps through)" if drifting else ""))
    unflagged = "" if gap.get("significant", True) else (
        " (the nominal's residual tests had not flagged a gap; the withheld fit gain did)")
    rest = "; a significant gap remains: " + "; ".join(remaining.get("reasons", [])) \
        if remaining.get("significant") else ""
    return f"{' then '.join(effects)}: validation fit {fits}{unflagged}{rest}"


def _training_only(rounds: Sequence[Mapping[str, Any]], accepted: Sequence[str]
                   ) -> list[dict[str, Any]]:
    """The effects the training run supports decisively (``dBIC < -10``, ``|theta|/sigma > 3``)
    that were rejected only because the withheld run shows no gain (none made an output worse):
    the validation run does not excite them, so it can neither confirm nor refute them. From the
    last round (earlier rounds judged them against a model since changed); strongest training
    evidence first."""
    found = []
    for trial in (rounds[-1].get("tried", ()) if rounds else ()):
        effect = trial["effect"]
        failed = trial.get("failed", ())
        if effect in accepted or not failed or not all(f.startswith(NO_GAIN_REASONS) for f in failed):
            continue
        found.append({"effect": effect, "variant": trial["variant"],
                      "delta_bic": trial["delta_bic"], "improvement": trial["improvement"]})
    return sorted(found, key=lambda item: item["delta_bic"])


def _training_only_text(items: Sequence[Mapping[str, Any]]) -> str:
    if not items:
        return ""
    return ("; decisive on training but not shown by the withheld run (which does not excite "
            "them; a run that does would tell): " + ", ".join(
                f"{i['effect']} {i['variant']} (dBIC {i['delta_bic']:.0f}, validation "
                f"{i['improvement']:+.2f} points)" for i in items))


__all__ = ["diagnose", "fit_nominal", "Diagnosis", "Trial", "Step", "effective_samples"]
