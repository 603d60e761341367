"""Which passing candidate a round of the diagnosis accepts (step 3 of
:func:`~panto.identification.diagnosis.pipeline.diagnose`).

The largest withheld gain wins unless others come within its standard error over the blocked
folds (:func:`tolerance`); the training ``dBIC`` decides among those (:func:`choose`), after the
refits that could be chosen were continued to their optima where they stopped on their budget
(:func:`choose_converged`); the others the runs cannot tell from the chosen one are named beside
it (:func:`alternatives`).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.diagnosis.parallel import map_trials
from panto.identification.diagnosis.refit import (Model, Search, Trial, continue_refit,
                                                  stopped_on_budget)
from panto.identification.diagnosis.support import BIC_THRESHOLD


def choose(passing: Sequence[tuple[Trial, Model, np.ndarray]], folds: int
            ) -> tuple[Trial, Model, np.ndarray]:
    """The accepted candidate among those passing: the largest validation improvement, unless
    others come within its standard error over the blocked folds (``spread / sqrt(folds)``);
    the withheld data cannot tell those apart, so the training ``dBIC`` (which charges ``ln N_eff``
    per parameter: parsimony) decides among them. A mass in the force-sensor path (one parameter)
    and a compliant mode (three) can both improve a run excited below the mode; the simpler one
    wins unless the mode is better on the withheld data beyond its uncertainty."""
    best = max(passing, key=lambda t: t[0].improvement)[0]
    close = [t for t in passing if t[0].improvement >= best.improvement - tolerance(best, folds)]
    return min(close, key=lambda t: t[0].delta_bic)


def choose_converged(trials: list, candidates: Sequence[Mapping[str, Any]], model: Model,
                     current: np.ndarray, search: Search, pool: Any = None
                     ) -> tuple[list, tuple | None]:
    """`trials` (the first ones refits of `candidates`, in order; any after them, the offset
    between the runs, nothing to refit) with the contenders' refits continued, and
    :func:`choose`'s choice among the passing ones (None when none passes).

    A contender is a trial whose refit stopped on its budget and that could be chosen at its
    optimum: a passing one whose withheld gain is within :func:`tolerance` of the best passing
    gain (the training ``dBIC`` then decides between optima, not between where two budgets ran
    out: held-out three-mass/actuator_lag/1250), or a rejected one that gains as much and whose
    rejection is the training side's (``dBIC`` or ``|theta|/sigma``, taken where its budget ran
    out; when none passes, a gain above its own fold standard error); the demo's bellow lag, the
    round's largest withheld gain, was rejected for ``|theta|/sigma`` 2.5 after 400 simulations
    with the contact recursion in NumPy and passed at 4.6 with the compiled one. Each is continued
    once (:func:`~panto.identification.diagnosis.refit.continue_refit`: three times the budget)
    and judged again, until no contender is left; so the chosen effect's parameters, the next
    round's start and the gap it closes are those of its optimum (the demo's contact loss and
    friction both stopped on 400 simulations), and a refit the withheld run no longer supports
    at its optimum is not chosen. Contenders due together are continued side by side on `pool`
    (:func:`~panto.identification.diagnosis.parallel.map_trials`; the result is the serial one)."""
    trials, folds = list(trials), search.options.folds
    while True:
        passing = [t for t in trials if t[0].accepted]
        best = max(passing, key=lambda t: t[0].improvement)[0] if passing else None
        floor = best.improvement - tolerance(best, folds) if best is not None else -math.inf
        due = [i for i, (trial, _, _) in enumerate(trials[:len(candidates)])
               if stopped_on_budget(trial) and not trial.continuation and
               _contends(trial, floor, folds)]
        if not due:
            return trials, (choose(passing, folds) if passing else None)
        done = map_trials(_continued, model, [(candidates[i], trials[i]) for i in due], current,
                          search, pool)
        for i, entry in zip(due, done):
            trials[i] = entry


def _continued(model: Model, item: tuple, current: np.ndarray, search: Search) -> tuple:
    """:func:`~panto.identification.diagnosis.refit.continue_refit` of ``item = (candidate,
    entry)`` (a :func:`~panto.identification.diagnosis.parallel.map_trials` task)."""
    candidate, entry = item
    return continue_refit(candidate, entry, model, current, search)


#: The training-side rejections a refit stopped on its budget may owe to where the budget ran
#: out (:func:`~panto.identification.diagnosis.support.judge_trial`'s reasons).
TRAINING_SIDE = ("dBIC ", "|theta|/sigma ")


def _contends(trial: Trial, floor: float, folds: int) -> bool:
    """Whether `trial` could be chosen at its optimum (:func:`choose_converged`)."""
    if not math.isfinite(trial.improvement) or trial.improvement < floor:
        return False
    if trial.accepted:
        return True
    return (trial.improvement > tolerance(trial, folds) and bool(trial.failed) and
            all(reason.startswith(TRAINING_SIDE) for reason in trial.failed))


def tolerance(trial: Trial, folds: int) -> float:
    """The standard error of `trial`'s withheld gain over the blocked folds
    (``spread / sqrt(folds)``): gains closer than that to it the withheld run cannot tell apart."""
    return trial.fold_spread / math.sqrt(max(folds, 1)) if math.isfinite(trial.fold_spread) \
        else 0.0


def alternatives(chosen: Trial, passing: Sequence[tuple[Trial, Model, np.ndarray]],
                  folds: int) -> tuple[str, ...]:
    """The other passing candidates the runs cannot tell from `chosen`: a withheld gain within
    the chosen one's fold standard error (:func:`choose`) and a training ``dBIC`` less than 10
    away (Kass & Raftery 1995: below 10 the evidence for one over the other is not strong). A
    lag much shorter than the excitation's periods acts like a delay: on such a run both are
    named, the diagnosis' first (the lower ``dBIC``) and the other as equally supported."""
    within = tolerance(chosen, folds)
    return tuple(t.effect for t, _, _ in passing
                 if t.effect != chosen.effect and t.improvement >= chosen.improvement - within
                 and abs(t.delta_bic - chosen.delta_bic) < -BIC_THRESHOLD)


__all__ = ["choose", "choose_converged", "tolerance", "alternatives", "TRAINING_SIDE"]
