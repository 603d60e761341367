"""Plots of identification results, PNG files drawn on bare matplotlib figures.

* :func:`plot_fit`: measured against simulated free run per output, training and validation.
* :func:`plot_comparison`: the comparison of model structures as a bar chart of their fits.
* :func:`plot_validation`: each compared structure's free run on the validation data.
* :func:`plot_pareto`: the NSGA-II Pareto front of two fits (thesis Fig. 4.7).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from panto.identification.estimation.base import (IdentificationData, IdentificationError,
                                                  IdentificationResult, fit_percent)
from panto.identification.estimation.comparison import ComparisonTable
from panto.identification.estimation.genetic import PENALTY, ParetoResult


def plot_fit(result: IdentificationResult, data: IdentificationData, path: str | Path, *,
             validation: IdentificationData | None = None) -> Path:
    """Measured (grey) and simulated (black) free run per output; a column per data set."""
    from matplotlib.figure import Figure

    sets = [("training", data)] + ([("validation", validation)] if validation is not None else [])
    outputs = [o for o in result.fit]
    fig = Figure(figsize=(7 * len(sets), 2.6 * len(outputs)))
    axes = fig.subplots(len(outputs), len(sets), squeeze=False, sharex="col")
    for column, (label, d) in enumerate(sets):
        try:
            simulated = result.simulate(d)
        except (ValueError, ArithmeticError, RuntimeError):
            simulated = np.full((len(d), len(outputs)), np.nan)
        for row, name in enumerate(outputs):
            ax = axes[row, column]
            measured = d.output(name)
            fit = fit_percent(measured, simulated[:, row])
            ax.plot(d.time, measured, color="0.6", lw=0.8, label="measured")
            ax.plot(d.time, simulated[:, row], color="k", lw=0.8, label="simulated")
            ax.set_ylabel(f"{name} [{d.units.get(name, '')}]")
            ax.set_title(f"{label}: {name}, fit {fit:.1f} %", fontsize=9)
        axes[-1, column].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    fig.suptitle(f"{result.structure} ({result.method}), free run", fontsize=10)
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    fig.savefig(path, dpi=110)
    return Path(path)


def plot_comparison(table: ComparisonTable, out_png: str | os.PathLike, *,
                    floor: float = -100.0) -> str | os.PathLike:
    """Bar chart of the fits (training hatched, validation solid) per structure and output.

    Fits below `floor` are drawn at the floor and labelled with their value.
    """
    import matplotlib
    from matplotlib.figure import Figure

    rows = table.rows
    groups = [(o, on) for o in table.outputs for on in ("training", "validation")]
    width = 0.8 / len(groups)
    fig = Figure(figsize=(max(6.0, 1.4 * len(rows) + 2), 4.5))
    ax = fig.subplots()
    colours = matplotlib.colormaps["tab10"].colors
    lowest = 0.0
    for g, (output, on) in enumerate(groups):
        values = np.array([r.score(output, on) for r in rows])
        shown = np.where(np.isfinite(values), np.maximum(values, floor), 0.0)
        lowest = min(lowest, float(shown.min(initial=0.0)))
        x = np.arange(len(rows)) + (g - (len(groups) - 1) / 2) * width
        ax.bar(x, shown, width, color=colours[table.outputs.index(output) % 10],
               hatch="//" if on == "training" else None, alpha=0.6 if on == "training" else 1.0,
               edgecolor="k", linewidth=0.5, label=f"{output}, {on}")
        for xi, value in zip(x, values):
            if np.isfinite(value) and value < floor:
                ax.text(xi, floor, f"{value:.0f}", rotation=90, fontsize=7, va="bottom")
    for i, row in enumerate(rows):
        if row.result is None:
            ax.text(i, 2.0, "failed", ha="center", fontsize=8, color="tab:red")
    ax.set_xticks(range(len(rows)), [r.structure for r in rows], rotation=30, ha="right")
    ax.set_ylabel("fit [%]")
    ax.axhline(0.0, color="k", linewidth=0.8)
    ax.set_ylim(lowest - 5, 105)
    ax.set_title("Model structures: fit on training and validation (free run)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    fig.savefig(out_png, dpi=120)
    return out_png


def plot_validation(table: ComparisonTable, validation: IdentificationData,
                    folder: str | os.PathLike) -> list[Path]:
    """One PNG per identified structure: measured and simulated outputs on the validation run."""
    from matplotlib.figure import Figure

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for row in table.rows:
        if row.result is None:
            continue
        try:
            simulated = np.asarray(row.result.simulate(validation), float)
        except Exception:  # noqa: BLE001 - the row already says why
            continue
        fitted = list(row.result.fit)
        shown = [o for o in table.outputs if o in fitted]
        fig = Figure(figsize=(9.0, 2.6 * len(shown)))
        axes = fig.subplots(len(shown), 1, sharex=True, squeeze=False)
        for ax, output in zip(axes[:, 0], shown):
            unit = validation.units.get(output, "")
            fit = row.fit_validation.get(output)
            shown_fit = f"{fit:.1f}" if fit is not None and math.isfinite(fit) else "-"
            ax.plot(validation.time, validation.output(output), color="0.4", lw=0.8,
                    label="measured")
            ax.plot(validation.time, simulated[:, fitted.index(output)], color="k", lw=1.2,
                    label=f"simulated (fit {shown_fit} %)")
            ax.set_ylabel(f"{output} [{unit}]" if unit else output)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8, loc="upper right")
        axes[-1, 0].set_xlabel("time [s]")
        fig.suptitle(f"{row.structure}: validation ({validation.source or 'validation data'})")
        fig.tight_layout()
        fig.set_layout_engine(None)  # laid out: savefig draws once
        path = folder / f"validation_{row.structure}.png"
        fig.savefig(path, dpi=110)
        written.append(path)
    return written


def plot_pareto(result: ParetoResult, out_png: str | os.PathLike, *,
                picked: IdentificationResult | None = None,
                polished: IdentificationResult | None = None, title: str | None = None):
    """The Pareto front as thesis Fig. 4.7: fit on the cross bar against fit on the force.

    Grey: the final population; black: the non-dominated solutions; a star marks the picked
    solution and an arrow leads to it after LM polishing. Returns the written path.
    """
    from matplotlib.figure import Figure

    names = result.objective_names
    if len(names) < 2:
        raise IdentificationError("plot_pareto needs two objectives")
    fig = Figure(figsize=(6.0, 4.5))
    ax = fig.subplots()
    population = result.population_objectives
    shown = np.all(population > 100.0 - PENALTY, axis=1)
    ax.scatter(population[shown, 0], population[shown, 1], s=12, c="0.75", label="population")
    ax.scatter(result.objectives[:, 0], result.objectives[:, 1], s=22, c="k",
               label="non-dominated")
    marks = [(picked, "picked", "tab:red", "*"), (polished, "after LM polish", "tab:green", "D")]
    points = {}
    for choice, label, colour, marker in marks:
        if choice is not None and all(n in choice.fit for n in names[:2]):
            points[label] = (choice.fit[names[0]], choice.fit[names[1]])
            ax.scatter(*points[label], s=120, c=colour, marker=marker, label=label, zorder=3)
    if len(points) == 2:
        ax.annotate("", xy=points["after LM polish"], xytext=points["picked"],
                    arrowprops={"arrowstyle": "->", "color": "tab:green"})
    ax.set_xlabel(f"fit on {names[0]} [%]")
    ax.set_ylabel(f"fit on {names[1]} [%]")
    ax.set_title(title or f"Pareto front, {result.structure.name} ({result.n_evaluations} "
                          "evaluations)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    fig.savefig(out_png, dpi=120)
    return out_png


__all__ = ["plot_fit", "plot_comparison", "plot_validation", "plot_pareto"]
