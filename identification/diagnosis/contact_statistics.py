"""Withheld evidence for a contact loss that no model reproduces sample by sample.

A head that leaves the wire and lands again is a sensitive system: the instant of each landing
depends on the last bits of the state, so two integrations of the same flying pantograph drift
apart (the benchmark plants' own free run at half the step differs by tens of fit points), and a
refitted contact loss can validate *worse* sample by sample than the smooth bilateral nominal
although it is the cause. What such a model does reproduce is the contact force's distribution:
EN 50318 validates a pantograph-catenary simulation by statistics of the contact force (mean,
standard deviation, statistical extremes and the like over the analysed section; reference
``catenary_en50318.md``), not by its time series.

:func:`statistics_evidence` compares the distribution of the force on the withheld run, measured
against simulated, before and after the candidate, by the misfit of its quantiles
:data:`QUANTILES` (root mean square of the quantile differences, in standard deviations of the
measured force), on the whole run and on each blocked fold. The contact loss passes on this
evidence when it at least halves the whole-run misfit and lowers it on every fold: a bilateral
model predicts pulling forces a real contact never shows, so on a flying head the difference is
large and the same on every part of the run; where the head never leaves the wire, the two
models' distributions do not differ and the test cannot pass.
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
    y = validation.outputs[:, j]
    scale = float(np.nanstd(y))
    before = quantile_misfit(y, current[:, j], scale)
    after = quantile_misfit(y, simulated[:, j], scale)
    pairs = [(quantile_misfit(y[b], current[b, j], scale),
              quantile_misfit(y[b], simulated[b, j], scale))
             for b in np.array_split(np.arange(len(y)), max(1, folds))]
    every_fold = all(a < b for b, a in pairs)
    accepted = bool(after <= KEPT_SHARE * before and every_fold)
    reason = (f"{output}'s distribution on the withheld run (quantiles {QUANTILES[0]:g}-"
              f"{QUANTILES[-1]:g}) misfit {before:.2f} -> {after:.2f} standard deviations"
              f"{', lower on every fold' if every_fold else ', not lower on every fold'}")
    return {"accepted": accepted, "before": before, "after": after, "folds": pairs,
            "reason": reason}


__all__ = ["QUANTILES", "KEPT_SHARE", "quantile_misfit", "statistics_evidence"]
