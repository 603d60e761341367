"""Withheld evidence for a contact loss that no model reproduces sample by sample.

A head that leaves the wire and lands again is a sensitive system: the instant of each landing
depends on the last bits of the state, so two integrations of the same flying pantograph drift
apart (the benchmark plants' own free run at half the step differs by tens of fit points), and a
refitted contact loss can validate *worse* sample by sample than the smooth bilateral nominal
although it is the cause. What such a model does reproduce is the contact force's distribution:
EN 50318 validates a pantograph-catenary simulation by statistics of the contact force (mean,
standard deviation, statistical extremes and the like over the analysed section; reference
``catenary_en50318.md``), not by its time series.

:func:`statistics_evidence` compares the distribution of the force on the withheld run,
measured against simulated, before and after the candidate, by the misfit of its quantiles
:data:`QUANTILES` (root mean square of the quantile differences, in standard deviations of the
measured force), on the whole run and on each blocked fold, over the samples where all three are
finite. It is asked only where the mechanism shows: the current (bilateral) model pulls the head,
its force below zero on at least :data:`PULLING_SHARE` of the withheld samples, or the measured
force is below zero on as many (a head off the wire reads its sensor's noise about zero, half of
it below; a bilateral nominal fitted to a flying head bends until it predicts no pull at all:
seen held-out two-mass/contact_loss/4358, the head flying in the run's last quarter only), and
the candidate does not pull (its force below zero on less than a tenth of the larger share); the
refit of a contact loss also retunes the nominal, and a head that never leaves the wire would
otherwise pass on a corrected amplitude or offset alone. The contact loss then passes when it at
least halves the whole-run misfit and lowers it on every fold where the mechanism shows (a head
may fly in one part of the run only: elsewhere the two models differ only by the refit's
retuning).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from panto.identification.estimation.base import IdentificationData

#: Quantiles of the contact force compared (its bulk and both tails).
QUANTILES = (0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99)
#: Share of the bilateral model's quantile misfit the candidate may leave on the whole run.
KEPT_SHARE = 0.5
#: Share of the withheld samples on which the current model's force must pull (be negative) for
#: the distribution to be asked (the lowest quantile compared).
PULLING_SHARE = QUANTILES[0]


def below_zero(force: np.ndarray) -> float:
    """The share of `force`'s samples below zero (a NaN is not): a bilateral model pulling the
    head, or a measured head off the wire reading its sensor's noise about zero; the mechanism
    shows where it reaches :data:`PULLING_SHARE`."""
    force = np.asarray(force, float)
    return float(np.mean(force < 0.0)) if force.size else 0.0


def quantile_misfit(measured: np.ndarray, simulated: np.ndarray, scale: float) -> float:
    """Root mean square of the differences of the :data:`QUANTILES` of `simulated` and
    `measured` (finite samples of both), divided by `scale`; NaN without samples."""
    ok = np.isfinite(measured) & np.isfinite(simulated)
    if not ok.any() or not scale > 0:
        return math.nan
    difference = np.quantile(simulated[ok], QUANTILES) - np.quantile(measured[ok], QUANTILES)
    return float(np.sqrt(np.mean(difference ** 2)) / scale)


def statistics_evidence(validation: IdentificationData, current: np.ndarray,
                        simulated: np.ndarray, output: str, folds: int) -> dict[str, Any]:
    """Whether the candidate's free run `simulated` reproduces the distribution of `output` on
    the withheld run better than the current model's `current` (module notes).

    Returns ``accepted``, the whole-run misfits ``before`` and ``after`` [standard deviations of
    the measured output], the per-fold pairs ``folds`` and a ``reason`` sentence.
    """
    j = list(validation.output_names).index(output)
    ok = np.isfinite(validation.outputs[:, j]) & np.isfinite(current[:, j]) & \
        np.isfinite(simulated[:, j])
    y, c, s = validation.outputs[ok, j], current[ok, j], simulated[ok, j]
    scale = float(np.std(y)) if y.size else 0.0
    if not (scale > 0 and y.size >= 10 * max(1, folds)):
        return {"accepted": False, "before": math.nan, "after": math.nan, "folds": [],
                "reason": f"{output} has too few finite samples or no spread on the withheld run"}
    pulling, still, floor = below_zero(c), below_zero(s), below_zero(y)
    shows = max(pulling, floor)
    if not (shows >= PULLING_SHARE and still < 0.1 * shows):
        return {"accepted": False, "before": math.nan, "after": math.nan, "folds": [],
                "reason": f"the current model pulls on {100 * pulling:.1f} % of the withheld "
                          f"samples, the measured force is below zero on {100 * floor:.1f} %, "
                          f"the candidate pulls on {100 * still:.1f} %: no contact lost"}
    before, after = quantile_misfit(y, c, scale), quantile_misfit(y, s, scale)
    blocks = np.array_split(np.arange(len(y)), max(1, folds))
    pairs = [(quantile_misfit(y[b], c[b], scale), quantile_misfit(y[b], s[b], scale))
             for b in blocks]
    acting = [pair for b, pair in zip(blocks, pairs)
              if max(below_zero(c[b]), below_zero(y[b])) >= PULLING_SHARE]
    every_fold = all(a < b for b, a in acting)
    accepted = bool(after <= KEPT_SHARE * before and every_fold)
    reason = (f"{output}'s distribution on the withheld run (quantiles {QUANTILES[0]:g}-"
              f"{QUANTILES[-1]:g}) misfit {before:.2f} -> {after:.2f} standard deviations, "
              f"{'lower' if every_fold else 'not lower'} on every fold where the bilateral "
              f"model pulls or the measured force is below zero ({len(acting)} of "
              f"{len(blocks)}; on {100 * pulling:.1f} and {100 * floor:.1f} % of the samples)")
    return {"accepted": accepted, "before": before, "after": after, "folds": pairs,
            "reason": reason}


__all__ = ["QUANTILES", "KEPT_SHARE", "PULLING_SHARE", "below_zero", "quantile_misfit",
           "statistics_evidence"]
