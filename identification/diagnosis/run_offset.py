"""An offset that changes between the runs: the ``offset`` candidate's *between runs* variant.

A force sensor re-zeroed (or drifted) between two runs, a preload or a laser's mounting shifted
between them, moves one output by a constant on the withheld run only. The training run cannot
show it: the nominal's own constant (the static force ``F_0``, the position offset) absorbs
whatever zero the training run had, so the ``offset`` refit on training changes nothing, and the
gap the withheld run shows is a constant the library's effects cannot produce (before this variant
the diagnosis answered ``unexplained`` on every such case of the independent families).

The test, out of sample like every other: the shift of output ``j`` is measured on the FIRST of
the ``K`` blocked folds of the withheld run (a tare at the start of the run) as the mean residual
``d = mean(y - y_hat)`` there, and applied to the other folds only; the first fold is left
unchanged, so it contributes no improvement. The variant is then judged like a refitted candidate
(:func:`~panto.identification.diagnosis.support.judge_trial`'s tests that apply): ``|d| /
sigma_d > 3`` with ``sigma_d`` from the first fold's residual and its effective sample size, the
whole-run improvement above the folds' standard error, some output better by the relevance floor
and none worse beyond chance. A residual whose mean is not a constant of the run (a dynamic effect,
a slow drift) fails on the other folds. The training ``dBIC`` does not apply (the training run
cannot tell a between-run change), it is reported as 0 (no evidence against it, the rule of a
parameterless switch).

The shift is a property of the withheld run, not of the model: the model's parameters do not
change, and later rounds judge their candidates with the shift added to their free runs
(:attr:`~panto.identification.diagnosis.refit.Search.validation_shift`).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from panto.identification.diagnosis.support import (IMPROVEMENT_FLOOR, NO_GAIN_REASONS,
                                                    SIGNIFICANCE, effective_samples,
                                                    withheld_gain)

VARIANT = "between runs"
#: Share of the output's residual energy (outside the first fold) a between-run offset must remove:
#: a constant that is only part of a residual whose mean wanders with the excitation's history
#: (hysteresis, a head bouncing off the wire) is not a change between the runs.
MAIN_PART = 0.5


def shifts(validation: Any, current: np.ndarray, folds: int) -> list[dict[str, Any]]:
    """Per output: the first fold's mean residual ``d`` [output unit], its standard error, the
    free run with ``d`` added outside the first fold and that mask (``rest``) (`current`: the
    model's free run on the withheld run, shape (N, outputs))."""
    y = np.asarray(validation.outputs, float)
    rest = np.ones(len(y), bool)
    first = np.array_split(np.arange(len(y)), max(1, folds))[0]
    rest[first] = False
    out = []
    for j, name in enumerate(validation.output_names):
        residual = y[first, j] - current[first, j]
        residual = residual[np.isfinite(residual)]
        if residual.size < 10:
            continue
        d = float(np.mean(residual))
        spread = float(np.std(residual - d, ddof=1))
        error = spread / math.sqrt(max(effective_samples(residual - d), 1.0))
        shifted = np.array(current, float, copy=True)
        shifted[rest, j] += d
        out.append({"output": name, "shift": d, "std": error, "simulated": shifted,
                    "rest": rest})
    return out


def judge_shift(shift: dict[str, Any], validation: Any, current: np.ndarray,
                folds: int) -> dict[str, Any]:
    """The acceptance tests that apply to a between-run shift (module notes); the fields of a
    :class:`~panto.identification.diagnosis.refit.Trial`."""
    name, simulated = shift["output"], shift["simulated"]
    y = np.asarray(validation.outputs, float)
    gain = withheld_gain(validation, current, simulated, folds)
    fit_after, improvement = gain["fit_after"], gain["improvement"]
    per_fold, spread, standard_error = gain["per_fold"], gain["spread"], gain["standard_error"]
    significance = abs(shift["shift"]) / shift["std"] if shift["std"] > 0 else math.inf
    j, rest = list(validation.output_names).index(name), shift["rest"]
    before = y[rest, j] - current[rest, j]
    share = 1.0 - float(np.nansum((before - shift["shift"]) ** 2) / np.nansum(before ** 2))
    failed = gain["failed"]
    if not share >= MAIN_PART:
        failed.append(f"removes {100 * share:.0f} % of {name}'s residual energy outside the "
                      f"first fold (an offset between runs is named only as its main part, "
                      f">= {100 * MAIN_PART:.0f} %)")
    if not significance > SIGNIFICANCE:
        failed.append(f"|theta|/sigma {significance:.2f} <= {SIGNIFICANCE:g}")
    if not gain["best"] >= IMPROVEMENT_FLOOR:
        failed.append(f"{NO_GAIN_REASONS[0]} by {IMPROVEMENT_FLOOR:g} points "
                      f"(best {gain['best']:.2f})")
    if not (improvement > standard_error and improvement > 0):
        failed.append(f"{NO_GAIN_REASONS[1]} {improvement:.2f} not above the folds' standard "
                      f"error {standard_error:.2f}")
    key = f"offset:{name}:{VARIANT.replace(' ', '_')}"
    return {"effect": "offset", "variant": VARIANT, "err": 0.0,
            "description": (f"offset of {name} between the runs: {shift['shift']:+.4g} on the "
                            f"withheld run (measured on its first of {folds} folds, applied to "
                            "the others)"),
            "parameters": {key: shift["shift"]}, "std": {key: shift["std"]},
            "significance": significance, "delta_bic": 0.0, "improvement": improvement,
            "fold_improvements": tuple(per_fold), "fold_spread": spread, "fit_train": {},
            "fit_validation": fit_after, "accepted": not failed, "failed": tuple(failed),
            "message": (f"judged on the withheld run's folds 2..K; removes {100 * share:.0f} % "
                        f"of {name}'s residual energy there")}


__all__ = ["VARIANT", "shifts", "judge_shift"]
