"""Backward elimination after the search (step 3, last part, of
:func:`~panto.identification.diagnosis.pipeline.diagnose`).

The forward search accepts one effect per round, each judged against the model of the rounds
before it. An effect accepted early can be made superfluous by one accepted later: a large
actuator lag or input delay that the nominal cannot express is first imitated by an extra mode
(its phase, over the excited band), which wins round 1; the lag itself is accepted in round 2 on
top of it, and the mode it imitated then adds nothing (seen held-out three-mass/actuator_lag/4490
and two-mass/actuator_lag/4565: ``extra_mode`` then ``actuator_lag``).

So once two or more effects are accepted, each is removed in turn and the model of the others
refitted on the training run (least squares from the full model's values; the removed effect's
own parameters gone). An effect is kept only when the full model still gains on the withheld run
over the model without it by the forward search's own withheld tests
(:func:`~panto.identification.diagnosis.support.no_withheld_gain`: a best output improving by the
relevance floor, a mean gain above the folds' standard error or, for a contact loss, a local
``t`` above :data:`~panto.identification.diagnosis.support.LOCAL_T`). Of the effects that fail it, the one
whose removal costs least is dropped and the elimination repeats on the rest. No new threshold:
model selection on the withheld run with the tests every effect passed to be accepted.

Not applied when an accepted effect passed on its force's distribution rather than sample by
sample (its free run need not follow the record), or when an offset between the runs was
accepted (a property of the withheld run, not of the model's structure).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from panto.identification.diagnosis.augmentations import (AugmentedStructure,
                                                          describe_augmentation)
from panto.identification.diagnosis.parallel import map_trials
from panto.identification.diagnosis.refit import Model, Search, Trial, long_refit
from panto.identification.diagnosis.support import (Refit, judge_trial, local_gain_may_pass,
                                                     no_withheld_gain, withheld_gain)
from panto.identification.estimation.base import IdentificationError, ModelStructure

_FAILURES = (IdentificationError, ValueError, ArithmeticError, np.linalg.LinAlgError)


def layers(structure: ModelStructure, base: ModelStructure
           ) -> list[tuple[str, dict[str, Any]]] | None:
    """The effects stacked on `base` to make `structure`, innermost first, as ``(effect,
    setting)``; None when `structure` is not `base` (or a copy of it: refits in worker processes
    come back pickled) with augmentations on it."""
    found = []
    while isinstance(structure, AugmentedStructure):
        found.append((structure.effect, dict(structure.setting)))
        structure = structure.nominal_structure
    same = type(structure) is type(base) and structure.name == base.name and \
        tuple(structure.parameter_names) == tuple(base.parameter_names)
    return found[::-1] if same else None


def refit_layers(model: Model, kept: Sequence[tuple[str, Mapping[str, Any]]],
                 base: ModelStructure, search: Search) -> tuple[Model, Any, np.ndarray]:
    """`base` with the `kept` effects stacked on it, refitted on the training run from `model`'s
    values (its free parameters that the stack still has) with a continued refit's budget
    (:func:`~panto.identification.diagnosis.refit.long_refit`: removing an effect moves the
    optimum of the rest), and its free run on the validation run."""
    structure = base
    for effect, setting in kept:
        structure = AugmentedStructure(structure, effect, search.roles, setting)
    names = set(structure.parameter_names)
    result, reduced, simulated = long_refit(
        structure, tuple(n for n in model.free if n in names),
        {n: v for n, v in model.parameters.items() if n in names}, search)
    return reduced, result, simulated


def _without(model: Model, item: tuple, current: np.ndarray, search: Search) -> dict[str, Any]:
    """The model without effect ``item[0]`` of the stack ``item[1]`` on ``item[2]``, refitted,
    and whether the full model (free run `current`) gains over it on the withheld run (a
    :func:`~panto.identification.diagnosis.parallel.map_trials` task)."""
    index, stack, base = item
    try:
        reduced, result, simulated = refit_layers(
            model, [layer for k, layer in enumerate(stack) if k != index], base, search)
    except _FAILURES as error:
        search.say(f"  without {stack[index][0]}: refit failed ({error}); kept")
        return {"index": index, "failed": [], "why": f"refit failed ({error})"}
    gain = withheld_gain(search.validation, simulated, current, search.options.folds)
    failed = no_withheld_gain(gain, search.validation, simulated, current,
                              local=local_gain_may_pass(stack[index][0]))
    search.say(f"  without {stack[index][0]} (the rest refitted: {result.message}): the full "
               f"model gains {gain['improvement']:+.2f} points on the withheld run (folds' "
               f"standard error {gain['standard_error']:.2f}): " +
               ("dispensable (" + "; ".join(failed) + ")" if failed else "needed"))
    return {"index": index, "failed": failed, "model": reduced, "result": result,
            "simulated": simulated, "improvement": gain["improvement"],
            "standard_error": gain["standard_error"]}


def eliminate(nominal: Model, model: Model, current: np.ndarray, accepted: Sequence[str],
              search: Search, pool: Any = None) -> dict[str, Any] | None:
    """Backward elimination of the `accepted` effects of `model` (free run `current` on the
    validation run) down to those the withheld run needs (module notes); the rounds' refits on
    `pool`. None when nothing is dropped (or it does not apply); else the kept stack's model,
    result, free run, the kept effects' indices into `accepted`, and what was dropped (index,
    effect, the full model's withheld gain over the model without it, its standard error)."""
    stack = layers(model.structure, nominal.structure)
    if len(accepted) < 2 or stack is None or [e for e, _ in stack] != list(accepted):
        return None
    search.say(f"diagnose: backward: each of {', '.join(accepted)} removed in turn, the rest "
               "refitted on the training run")
    indices, dropped, last = list(range(len(stack))), [], None
    while len(indices) >= 2:
        results = map_trials(_without, model, [(k, stack, nominal.structure)
                                                for k in range(len(stack))], current, search,
                             pool)
        dispensable = [r for r in results if r["failed"]]
        if not dispensable:
            break
        worst = min(dispensable, key=lambda r: r["improvement"])
        k = worst["index"]
        dropped.append({"index": indices[k], "effect": stack[k][0],
                        "improvement": worst["improvement"],
                        "standard_error": worst["standard_error"]})
        search.say(f"diagnose: backward: {stack[k][0]} dropped")
        model, current, last = worst["model"], worst["simulated"], worst
        stack, indices = stack[:k] + stack[k + 1:], indices[:k] + indices[k + 1:]
    if last is None:
        return None
    return {"model": model, "result": last["result"], "simulated": current, "kept": indices,
            "stack": stack, "dropped": dropped}


def rejudged(nominal: Model, before: np.ndarray, eliminated: Mapping[str, Any],
             trials: Sequence[Trial], search: Search) -> list[tuple[Trial, np.ndarray, np.ndarray]]:
    """The kept effects' steps after an elimination, as ``(trial, free run before, free run
    after)``: each judged against the model of the kept effects before it (``base`` plus the
    first ones, refitted from the final model's values; the last is the final model), so that
    each step's gain is the one it adds in the kept model. `trials` are the accepted trials of the
    search, in order."""
    stack, final = eliminated["stack"], eliminated["model"]
    previous, previous_run, out = nominal, before, []
    for count, index in enumerate(eliminated["kept"], start=1):
        if count == len(stack):
            model, result, simulated = final, eliminated["result"], eliminated["simulated"]
        else:
            model, result, simulated = refit_layers(final, stack[:count], nominal.structure,
                                                    search)
        accepted = trials[index]
        candidate = {"effect": accepted.effect, "variant": accepted.variant, "err": accepted.err}
        judged = judge_trial(candidate, Refit(model.structure, result, simulated), previous,
                             search.train, search.validation, previous_run, search.options.folds)
        out.append((Trial(**{**judged, "description": describe_augmentation(model.structure)}),
                    previous_run, simulated))
        previous, previous_run = model, simulated
    return out


def why_dropped(item: Mapping[str, Any]) -> str:
    """Why the elimination dropped one effect (`item`: one of :func:`eliminate`'s ``dropped``)."""
    return (f"dropped after the search: with the other effects refitted without it, the "
            f"withheld fit changes by {-item['improvement']:+.2f} points (folds' standard error "
            f"{item['standard_error']:.2f})")


def dropped_text(dropped: Sequence[Mapping[str, Any]]) -> str:
    """The summary's clause for the effects the elimination dropped."""
    return "".join(f"; {d['effect']} was accepted in round {d['index'] + 1} and "
                   + why_dropped(d) for d in dropped)


__all__ = ["eliminate", "rejudged", "layers", "refit_layers", "dropped_text", "why_dropped"]
