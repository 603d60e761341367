"""Plots of the co-simulation and of the rig excitation, PNG files drawn on bare matplotlib figures.

* :func:`plot_contact_force`: the contact force along the line, raw and low-passed, with the
  section's statistics (EN 50318).
* :func:`plot_uplift`: the contact-wire uplift under the pantograph and the maximum per support.
* :func:`plot_rig_sequence`: two periods of the rig's excitation (thesis Fig. 3.4).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def _shade_section(ax: Any, result: Any) -> None:
    ax.axvspan(*result.section, color="tab:green", alpha=0.08, lw=0, label="analysed section")


def plot_contact_force(result: Any, path: str | Path) -> Path:
    """Contact force along the line: raw, 20 Hz low-passed, mean and mean +- 3 sigma.

    `result` is a :class:`panto.catenary_cosim.master.CosimulationResult`; returns the PNG written.
    """
    from matplotlib.figure import Figure

    stats = result.statistics()
    settings = result.settings
    fig = Figure(figsize=(11, 4.5), layout="constrained")
    ax = fig.subplots()
    _shade_section(ax, result)
    ax.plot(result.position, result.contact_force, color="0.7", lw=0.6, label="raw")
    ax.plot(result.position, result.filtered_force(), color="tab:blue", lw=1.4,
            label="low-pass 20 Hz")
    for value, style, label in ((stats.mean, "-", f"mean {stats.mean:.1f} N"),
                                (stats.stat_max, "--", f"mean ± 3σ ({stats.std:.1f} N)"),
                                (stats.stat_min, "--", None)):
        ax.hlines(value, *result.section, colors="tab:red", linestyles=style, label=label)
    lost = result.contact_force <= 0.0
    if lost.any():
        ax.plot(result.position[lost], np.zeros(lost.sum()), "x", color="tab:red", ms=4,
                label=f"contact loss ({stats.loss_pct:.2f} % in section)")
    for x in result.support_positions:
        ax.axvline(x, color="0.85", lw=0.6, zorder=0)
    ax.set(xlabel="position along the line x [m] (grey lines: supports)",
           ylabel="contact force [N]",
           title=f"{settings.get('pantograph', {}).get('name', '')} on {settings.get('line')} "
                 f"at {settings.get('speed_kmh', 0):g} km/h")
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    summary = (f"section: mean {stats.mean:.1f} N, σ {stats.std:.1f} N\n"
               f"max {stats.max:.1f} N, min {stats.min:.1f} N (20 Hz)\n"
               f"uplift {stats.uplift_max_mm:.1f} mm, loss {stats.loss_pct:.2f} %")
    ax.text(0.01, 0.97, summary, transform=ax.transAxes, va="top", fontsize=8,
            bbox={"boxstyle": "round", "facecolor": "white", "alpha": 0.8})
    # the run may end against a pinned line end (a force spike): keep the scale on the rest
    top = 1.25 * max(stats.stat_max, float(np.quantile(result.contact_force, 0.995)))
    ax.set_ylim(min(0.0, float(np.min(result.contact_force))) - 5.0, top)
    fig.savefig(path, dpi=120)
    return Path(path)


def plot_uplift(result: Any, path: str | Path) -> Path:
    """Contact-wire uplift at the contact point along the line, and the maximum per support.

    `result` is a :class:`panto.catenary_cosim.master.CosimulationResult`; returns the PNG written.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.5), layout="constrained")
    ax = fig.subplots()
    _shade_section(ax, result)
    ax.plot(result.position, 1000.0 * (result.wire_height - result.static_wire_height),
            color="tab:blue", lw=1.2, label="uplift of the wire under the pantograph")
    peak = 1000.0 * result.support_uplift.max(axis=0)
    ax.plot(result.support_positions, peak, "v", color="tab:red", ms=7,
            label="maximum uplift at each support (steady arm)")
    for x, value in zip(result.support_positions, peak):
        ax.annotate(f"{value:.0f}", (x, value), textcoords="offset points", xytext=(0, 6),
                    ha="center", fontsize=8, color="tab:red")
    stats = result.statistics()
    ax.set(xlabel="position along the line x [m]", ylabel="contact-wire uplift [mm]",
           title=f"Contact-wire uplift (max at the supports of the section: "
                 f"{stats.uplift_max_mm:.1f} mm)")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=120)
    return Path(path)


def plot_rig_sequence(path: str | Path, time: np.ndarray, values: np.ndarray, period: float) -> None:
    """Two periods of the rig excitation `values` [m] at `time` [s], as thesis Fig. 3.4."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 3.5), layout="constrained")
    ax = fig.subplots()
    two = np.concatenate([time, time + period])
    ax.plot(two, 1000.0 * np.tile(values, 2), color="tab:blue")
    ax.axvline(period, color="0.6", lw=0.8, ls="--")
    ax.set(xlabel="time [s]", ylabel="contact-wire displacement [mm]",
           title=f"Rig excitation: two periods of {period:.2f} s")
    fig.savefig(path, dpi=120)


__all__ = ["plot_contact_force", "plot_uplift", "plot_rig_sequence"]
