"""Plots of the residual analysis (:mod:`panto.identification.diagnosis.residual_analysis`), PNG files.

- :func:`plot_spectra`: residual and measured Welch spectra with the per-band power ratio.
- :func:`plot_error_model`: ``|G_e|`` of the model error model with its confidence radius, the
  falsified frequencies marked (and ``|G_e / G|`` when known).
- :func:`plot_segments`: residual RMS and fit per sliding window.
- :func:`plot_correlations`: residual autocorrelation and input-residual cross-correlations with
  their bounds.
- :func:`plot_output_analysis`: all four for one output.
- :func:`plot_series`: measured, nominal and augmented validation outputs of a diagnosis, and
  their residuals.
- :func:`plot_bands`: residual power per band before and after each accepted effect.

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from panto.identification.diagnosis.residual_analysis import (
    CrossCorrelationTest,
    ErrorModel,
    OutputAnalysis,
    WhitenessTest,
)
from panto.identification.diagnosis.residual_energy import BandEnergy, SegmentEnergy


def _figure(rows: int = 1, height: float = 3.2):
    from matplotlib.figure import Figure

    figure = Figure(figsize=(8, height * rows))
    axes = figure.subplots(rows, 1, squeeze=False)
    return figure, axes[:, 0]


def _save(figure, path: str | Path) -> str:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(path, dpi=110)
    return str(path)


def plot_spectra(bands: BandEnergy, path: str | Path, *, title: str = "") -> str:
    """Residual vs measured power spectral density and the residual/measured ratio per band."""
    figure, (top, bottom) = _figure(2)
    f = bands.frequencies
    keep = f > 0
    top.loglog(f[keep], bands.measured_psd[keep], label="measured")
    top.loglog(f[keep], bands.residual_psd[keep], label="residual")
    top.set_ylabel("PSD [unit²/Hz]")
    top.set_title(title or "Where the gap lies in frequency")
    top.legend()
    edges = np.maximum(bands.band_edges, f[keep][0] if keep.any() else 1e-3)
    for low, high, ratio in zip(edges[:-1], edges[1:], bands.ratio):
        bottom.hlines(ratio, low, high, linewidth=3)
    bottom.axhline(1.0, color="grey", linestyle=":")
    bottom.set_xscale("log")
    bottom.set_yscale("log")
    bottom.set_xlabel("frequency [Hz]")
    bottom.set_ylabel("residual / measured power")
    return _save(figure, path)


def plot_error_model(model: ErrorModel, path: str | Path, *, title: str = "") -> str:
    """``|G_e|`` per input with its confidence radius; falsified frequencies marked."""
    figure, axes = _figure(len(model.input_names))
    f = model.frequencies
    for i, (axis, name) in enumerate(zip(axes, model.input_names)):
        magnitude = np.abs(model.response[i])
        floor = max(float(np.min(model.radius[i])), 1e-300)
        axis.fill_between(f, floor, model.radius[i], color="grey", alpha=0.3,
                          label="confidence radius")
        axis.plot(f, magnitude, label=f"|G_e| from {name}")
        axis.set_yscale("log")
        if model.excited is not None and not np.all(model.excited[i]):
            axis.fill_between(f, 0, 1, where=~model.excited[i], color="orange", alpha=0.12,
                              transform=axis.get_xaxis_transform(),
                              label="input not excited (not tested)")
        axis.plot(f[model.falsified[i]], magnitude[model.falsified[i]], "r.", markersize=3,
                  label="falsified")
        if model.relative_error is not None:
            twin = axis.twinx()
            twin.plot(f, model.relative_error[i], "k--", linewidth=0.8)
            twin.set_ylabel("|G_e / G|")
        axis.set_ylabel("|G_e|")
        axis.legend(loc="upper right", fontsize=8)
    axes[0].set_title(title or f"Model error model (ARX {model.order_a}/{model.order_b})")
    axes[-1].set_xlabel("frequency [Hz]")
    return _save(figure, path)


def plot_segments(segments: SegmentEnergy, path: str | Path, *, title: str = "") -> str:
    """Residual RMS and fit [%] per window against the window start time."""
    figure, (top, bottom) = _figure(2, 2.6)
    centre = segments.start_times + 0.5 * segments.window
    top.plot(centre, segments.residual_rms, "o-")
    top.set_ylabel("residual RMS")
    top.set_title(title or f"Residual per {segments.window:.3g} s window")
    bottom.plot(centre, segments.fit, "o-")
    bottom.set_ylabel("fit [%]")
    bottom.set_xlabel("time [s]")
    return _save(figure, path)


def plot_correlations(whiteness: WhitenessTest, crosses: Sequence[CrossCorrelationTest],
                      path: str | Path, *, title: str = "") -> str:
    """Autocorrelation and cross-correlations with their bounds (MATLAB ``resid`` layout)."""
    figure, axes = _figure(1 + len(crosses), 2.4)
    axes[0].bar(whiteness.lags, whiteness.autocorrelation, width=0.6)
    axes[0].axhspan(-whiteness.bound, whiteness.bound, color="grey", alpha=0.3)
    axes[0].set_ylabel("r_eps(tau)")
    axes[0].set_title(title or f"Whiteness: Q = {whiteness.q_statistic:.3g}, "
                               f"p = {whiteness.p_value:.3g}")
    for axis, cross in zip(axes[1:], crosses):
        axis.bar(cross.lags, cross.correlation, width=0.6)
        axis.axhspan(-cross.bound, cross.bound, color="grey", alpha=0.3)
        axis.set_ylabel(f"r_eps,{cross.input_name}")
        if cross.hints:
            axis.set_title("; ".join(cross.hints), fontsize=8)
    axes[-1].set_xlabel("lag [samples]")
    return _save(figure, path)


def plot_output_analysis(analysis: OutputAnalysis, stem: str | Path) -> list[str]:
    """The four plots for one output, written as ``<stem>_<kind>.png``; returns their paths."""
    stem = str(stem)
    name = analysis.output_name
    return [plot_spectra(analysis.bands, f"{stem}_spectra.png", title=f"{name}: spectra"),
            plot_error_model(analysis.error_model, f"{stem}_error_model.png",
                             title=f"{name}: model error model"),
            plot_segments(analysis.segments, f"{stem}_segments.png", title=f"{name}: segments"),
            plot_correlations(analysis.whiteness, analysis.cross_correlation,
                              f"{stem}_correlations.png", title=f"{name}: correlations")]


def plot_series(diagnosis: Any, path: Path) -> Path:
    """Measured, nominal and augmented validation outputs (free run), and the residuals.

    `diagnosis` is a :class:`panto.identification.diagnosis.pipeline.Diagnosis`.
    """
    from matplotlib.figure import Figure

    series = diagnosis.series
    names = diagnosis.output_names
    figure = Figure(figsize=(9, 2.6 * 2 * len(names)))
    axes = figure.subplots(2 * len(names), 1, sharex=True, squeeze=False)
    t = series["time"]
    for j, name in enumerate(names):
        top, bottom = axes[2 * j, 0], axes[2 * j + 1, 0]
        top.plot(t, series["measured"][:, j], "k", lw=0.8, label="measured")
        top.plot(t, series["before"][:, j], lw=0.8, label=f"nominal ({diagnosis.fit_before[name]:.1f} %)")
        if diagnosis.effects:
            top.plot(t, series["after"][:, j], lw=0.8,
                     label=f"+ {', '.join(diagnosis.effects)} ({diagnosis.fit_after[name]:.1f} %)")
        top.set_ylabel(name)
        top.legend(fontsize=7, loc="upper right")
        bottom.plot(t, series["measured"][:, j] - series["before"][:, j], lw=0.6, label="nominal")
        if diagnosis.effects:
            bottom.plot(t, series["measured"][:, j] - series["after"][:, j], lw=0.6, label="augmented")
        bottom.set_ylabel(f"residual {name}")
        bottom.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(path, dpi=90)
    return path


def plot_bands(diagnosis: Any, path: Path) -> Path | None:
    """Residual power per band before and after each accepted effect (None without effects).

    `diagnosis` is a :class:`panto.identification.diagnosis.pipeline.Diagnosis`.
    """
    if not diagnosis.steps:
        return None
    from matplotlib.figure import Figure

    names = diagnosis.output_names
    figure = Figure(figsize=(8, 2.8 * len(names)))
    axes = figure.subplots(len(names), 1, squeeze=False)
    for j, name in enumerate(names):
        axis = axes[j, 0]
        first = diagnosis.steps[0].bands[name]
        edges = np.asarray(first["edges_hz"])
        centres = np.arange(len(edges) - 1)
        axis.bar(centres - 0.2, first["before"], 0.4 / len(diagnosis.steps) + 0.2, label="nominal")
        for k, step in enumerate(diagnosis.steps):
            axis.bar(centres + 0.2 + 0.1 * k, step.bands[name]["after"], 0.2,
                     label=f"+ {step.effect}")
        axis.set_yscale("log")
        axis.set_xticks(centres, [f"{a:.2g}-{b:.2g}" for a, b in zip(edges[:-1], edges[1:])],
                        fontsize=7)
        axis.set_ylabel(f"residual power {name}")
        axis.legend(fontsize=7)
    axes[-1, 0].set_xlabel("band [Hz]")
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(path, dpi=90)
    return path
