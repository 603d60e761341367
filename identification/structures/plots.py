"""Plots of the model structures' own analyses, PNG files drawn on bare matplotlib figures.

* :func:`plot_collector_head`: Bode plots of the collector-head fits against the H1 estimates
  (thesis Figs. 4.5, 4.6).
* :func:`plot_eigenvalue_sensitivity`: the eigenvalues of the linearised model with each
  parameter scaled, and the influence ranking (thesis Fig. 4.9).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from panto.identification.structures.collector_head import CollectorHeadResult, pt2_response
from panto.identification.structures.sensitivity import EigenvalueSensitivity


def plot_collector_head(result: CollectorHeadResult, out_png: str | Path) -> Path:
    """Bode plots of the fits against the H1 estimates (thesis Figs. 4.5, 4.6), as a PNG."""
    from matplotlib.figure import Figure

    f = result.frequency[1:]
    panels = [("F -> dY, eq. 4.15", result.response_force[1:], result.full, "force"),
              ("y_cb -> dY, eq. 4.15", result.response_cross_bar[1:], result.full, "cross_bar"),
              ("F -> dY, eq. 4.16", result.response_force_only[1:], result.force_only, "force")]
    figure = Figure(figsize=(13, 6.5))
    axes = figure.subplots(2, 3, sharex=True)
    for column, (title, measured, fit, path) in enumerate(panels):
        model = pt2_response(fit, f, path)
        axes[0, column].semilogx(f, 20 * np.log10(np.abs(measured)), color="0.6", label="H1 estimate")
        axes[0, column].semilogx(f, 20 * np.log10(np.abs(model)), "k", label=(
            f"PT2: m {fit.mass:.2f} kg, c {fit.damping:.1f} N s/m, k {fit.stiffness:.0f} N/m"))
        axes[1, column].semilogx(f, np.degrees(np.unwrap(np.angle(measured))), color="0.6")
        axes[1, column].semilogx(f, np.degrees(np.unwrap(np.angle(model))), "k")
        axes[0, column].set_title(title)
        axes[0, column].legend(fontsize=7)
        for row in (0, 1):
            axes[row, column].axvspan(result.reliable_up_to_hz, f[-1], color="0.93")
            axes[row, column].grid(True, which="both", alpha=0.3)
        axes[1, column].set_xlabel("frequency [Hz]")
    axes[0, 0].set_ylabel("magnitude [dB]")
    axes[1, 0].set_ylabel("phase [deg]")
    figure.suptitle(f"Collector head {result.source} (shaded: above {result.reliable_up_to_hz:g} Hz)")
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    return out


def plot_eigenvalue_sensitivity(result: EigenvalueSensitivity, out_png: str | os.PathLike,
                                *, highlight: int = 4) -> str | os.PathLike:
    """Thesis Fig. 4.9 beside a bar chart of the ranking; returns the written path.

    Left: the eigenvalues in the complex plane (upper half), nominal as dots, the first factor
    as circles and the second as crosses; the `highlight` most influential parameters in colour,
    the rest in grey. Right: the relative eigenvalue shift per parameter, most influential first.
    """
    import matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11.0, 4.5))
    plane, bars = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 2]})
    colours = dict(zip(result.ranking[:highlight], matplotlib.colormaps["tab10"].colors))
    markers = ("o", "x", "s", "+", "^", "v")
    upper = result.nominal.imag >= 0
    for shift in result.shifts:
        colour = colours.get(shift.name, "0.6")
        for index, (factor, row) in enumerate(zip(shift.factors, shift.eigenvalues)):
            marker = markers[index % len(markers)]
            plane.scatter(row[upper].real, row[upper].imag, marker=marker, s=28,
                          facecolors="none" if marker in "os^v" else colour,
                          edgecolors=colour if marker in "os^v" else None, linewidths=1.0,
                          label=f"{shift.name} x{factor:g}" if shift.name in colours else None)
    plane.scatter(result.nominal[upper].real, result.nominal[upper].imag, c="k", s=14,
                  label="nominal", zorder=3)
    plane.set_xlabel("Re(lambda) [1/s]")
    plane.set_ylabel("Im(lambda) [1/s]")
    plane.set_title(f"Eigenvalues at eta = {result.eta:g} m, p = {result.p:g} bar")
    plane.grid(True, alpha=0.3)
    plane.legend(fontsize=7, ncol=2)
    ranking = result.ranking
    shifts = [100 * result.shift(n).relative_shift for n in ranking]
    bars.barh(range(len(ranking)), shifts, color=[colours.get(n, "0.6") for n in ranking])
    bars.set_yticks(range(len(ranking)), ranking)
    bars.invert_yaxis()
    factors = ", ".join(f"{f:g}" for f in result.shifts[0].factors) if result.shifts else ""
    bars.set_xlabel(f"max |eigenvalue shift| / |eigenvalue| [%] (factors {factors})")
    bars.set_title("Influence ranking")
    bars.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    fig.savefig(out_png, dpi=120)
    return out_png


__all__ = ["plot_collector_head", "plot_eigenvalue_sensitivity"]
