"""The closed-loop experiment's picture: predicted against achieved uncertainty per parameter.

:func:`plot_closed_loop` draws a :class:`panto.identification.design.closed_loop.ClosedLoopResult`
on a bare :class:`matplotlib.figure.Figure` (no pyplot, no backend chosen):

* top: relative standard deviation [%] of every parameter (its std over the magnitude of the
  truth, or of the joint estimate when the truth is unknown; the absolute values with units are
  in the table), log scale: after run 1 (predicted, achieved), after runs 1 + 2 (predicted,
  achieved) and the Cramer-Rao bound after runs 1 + 2; the identifiability thresholds (10 %
  weakly, 50 % not identifiable) as lines;
* bottom: the shrink factor (std after run 1 over std after runs 1 + 2), predicted and achieved,
  log scale, with :math:`\\sqrt 2` (what a repeat of run 1 gives) as a line.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


def _relative(result: Any) -> dict[str, np.ndarray]:
    """Relative std [%] per column of the plot, per parameter."""
    scale = np.array([abs(p.truth) if math.isfinite(p.truth) and p.truth != 0
                      else abs(p.estimate_joint) or 1.0 for p in result.parameters])
    columns = {"run 1 predicted": "predicted_std_first", "run 1 achieved": "std_first",
               "runs 1+2 predicted": "predicted_std_joint", "runs 1+2 achieved": "std_joint",
               "runs 1+2 Cramer-Rao bound": "bound_std_joint"}
    return {label: 100.0 * np.array([getattr(p, name) for p in result.parameters]) / scale
            for label, name in columns.items()}


def plot_closed_loop(result: Any, path: str | Path, *, threshold: float = 0.5) -> Path:
    """Write the closed-loop picture (module notes) to `path` (PNG) and return it.

    Parameters
    ----------
    result : ClosedLoopResult
    path : str or pathlib.Path
    threshold : float
        Relative std above which a parameter is not identifiable (a fifth of it: weakly).
    """
    from matplotlib.figure import Figure

    names = [f"{p.name}\n[{p.unit}]" for p in result.parameters]
    x = np.arange(len(names))
    figure = Figure(figsize=(max(7.0, 0.75 * len(names) + 2.0), 7.5), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    styles = {"run 1 predicted": ("x", "0.45", 0), "run 1 achieved": ("o", "0.45", 0),
              "runs 1+2 predicted": ("x", "C0", 1), "runs 1+2 achieved": ("o", "C0", 1),
              "runs 1+2 Cramer-Rao bound": ("_", "C3", 1)}
    for label, values in _relative(result).items():
        marker, colour, side = styles[label]
        style = ({"facecolors": "none", "edgecolors": colour, "s": 60} if marker == "o"
                 else {"color": colour, "s": 70})
        top.scatter(x + (0.15 if side else -0.15), values, marker=marker, label=label,
                    linewidths=1.6, zorder=3, **style)
    for level, text in ((100 * threshold, "not identifiable above"),
                        (100 * threshold / 5, "weakly identifiable above")):
        top.axhline(level, color="0.6", linestyle=":", linewidth=1)
        top.annotate(text, (x[-1] + 0.45, level), ha="right", va="bottom", fontsize=7,
                     color="0.4")
    top.set_yscale("log")
    top.set_ylabel("relative standard deviation [%]")
    top.set_title(f"{result.structure}: {result.duration:g} s APRBS, then {result.duration:g} s "
                  f"{'designed' if result.next_run == 'designed' else 'APRBS again'}")
    top.legend(fontsize=8, ncols=3, loc="lower left", framealpha=0.9)
    top.grid(True, which="major", axis="y", alpha=0.3)
    predicted = [p.predicted_shrink for p in result.parameters]
    achieved = [p.achieved_shrink for p in result.parameters]
    bottom.scatter(x - 0.1, predicted, marker="x", color="C0", s=60, label="predicted")
    bottom.scatter(x + 0.1, achieved, marker="o", facecolors="none", edgecolors="C0", s=50,
                   linewidths=1.6, label="achieved")
    bottom.axhline(math.sqrt(2.0), color="0.5", linestyle="--", linewidth=1,
                   label="repeat of run 1 ($\\sqrt{2}$)")
    bottom.axhline(1.0, color="0.7", linewidth=0.8)
    bottom.set_yscale("log")
    bottom.set_ylabel("std run 1 / std runs 1+2 [-]")
    bottom.legend(fontsize=8, ncols=3)
    bottom.grid(True, which="major", axis="y", alpha=0.3)
    bottom.set_xticks(x, names, fontsize=8)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=120)
    return path


__all__ = ["plot_closed_loop"]
