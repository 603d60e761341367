"""Which passing candidate a round of the diagnosis accepts (step 3 of
:func:`~panto.identification.diagnosis.pipeline.diagnose`).

The largest withheld gain wins unless others come within its standard error over the blocked
folds (:func:`tolerance`); the training ``dBIC`` decides among those (:func:`choose`), after their
refits stopped on their budget were continued to their optima, and those of rejected candidates
whose withheld gain reaches theirs (:func:`settle_ties`); the chosen
refit itself is continued when it stopped on its budget (:func:`choose_converged`); the others
the runs cannot tell from it are named beside it (:func:`alternatives`).
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

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
                      current: np.ndarray, search: Search) -> tuple[list, tuple | None]:
    """`trials` (the first ones refits of `candidates`, in order; any after them nothing to
    refit) and :func:`choose`'s choice among the passing ones (None when none passes), the
    chosen refit continued first when it stopped on its budget
    (:func:`~panto.identification.diagnosis.refit.continue_refit`; the trial in `trials`
    replaced): the accepted effect's parameters, the next round's start and the gap it closes
    are those of its optimum, not of where the budget ran out (the demo's contact loss and
    friction both stopped on 400 simulations). A continued refit the withheld run no longer
    supports is not chosen; the choice is made again among the others."""
    trials = list(trials)
    while True:
        passing = [t for t in trials if t[0].accepted]
        if not passing:
            return trials, None
        chosen = choose(passing, search.options.folds)
        index = next(i for i, t in enumerate(trials) if t is chosen)
        if index >= len(candidates) or chosen[0].continued or not stopped_on_budget(chosen[0]):
            return trials, chosen
        continued = continue_refit(candidates[index], chosen, model, current, search)
        if continued is chosen:  # the continuation failed or found nothing lower
            return trials, chosen
        trials[index] = continued


def tolerance(trial: Trial, folds: int) -> float:
    """The standard error of `trial`'s withheld gain over the blocked folds
    (``spread / sqrt(folds)``): gains closer than that to it the withheld run cannot tell apart."""
    return trial.fold_spread / math.sqrt(max(folds, 1)) if math.isfinite(trial.fold_spread) \
        else 0.0


def settle_ties(trials: list, candidates: Sequence[Mapping[str, Any]], model: Model,
                current: np.ndarray, search: Search) -> list:
    """`trials` (one per candidate, in order) with the contenders' refits continued where they
    stopped on their budget (:func:`~panto.identification.diagnosis.refit.continue_refit`) and
    judged again: the passing candidates the withheld run cannot tell apart (:func:`choose`'s
    tolerance), whose training ``dBIC`` then decides between optima, not between where two
    budgets ran out; and a rejected candidate whose refit stopped on its budget while its
    withheld gain already reaches theirs (at least the best passing gain less that tolerance;
    when none passes, above its own fold standard error): its significance and ``dBIC`` were
    taken where its budget ran out. (The demo's bellow lag, the round's largest withheld gain,
    was rejected for ``|theta|/sigma`` 2.5 after 400 simulations with the contact recursion in
    NumPy and accepted at 4.6 with the compiled one: where the budget ran out decided.)"""
    folds = search.options.folds
    passing = [t[0] for t in trials if t[0].accepted]
    best = max(passing, key=lambda t: t.improvement) if passing else None
    floor = best.improvement - tolerance(best, folds) if best is not None else -math.inf

    def contender(trial: Trial) -> bool:
        if trial.accepted:
            return trial.improvement >= floor
        return (stopped_on_budget(trial) and math.isfinite(trial.improvement)
                and trial.improvement >= floor and trial.improvement > tolerance(trial, folds))

    close = [t[0] for t in trials if contender(t[0])]
    if len(close) < 2 and all(t.accepted for t in close):
        return trials  # one passing candidate alone: choose_converged continues it if chosen
    continued = {id(t) for t in close}
    return [continue_refit(candidate, t, model, current, search) if id(t[0]) in continued
            else t for candidate, t in zip(candidates, trials)]


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


__all__ = ["choose", "choose_converged", "tolerance", "settle_ties", "alternatives"]
