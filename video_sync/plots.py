"""Plots of the video sidecar, PNG files drawn on bare matplotlib figures.

* :func:`plot_detection_steps`: the marker detection steps of one frame (thesis Fig. 3.10), for a
  user to check a tracker set-up.
* :func:`plot_synchronisation`: the LED correlation against the lag and the peak per start phase
  (thesis Fig. 3.8).

The figures are :class:`matplotlib.figure.Figure` objects (no pyplot, no backend chosen), so the
functions are safe in notebooks, scripts and servers.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from panto.video_sync.setup import read_frame
from panto.video_sync.synchronisation import SyncResult
from panto.video_sync.tracking import TrackerSetup, detect_marker, disk_footprint, similarity


def plot_detection_steps(video: str | Path, setup: TrackerSetup, frame_index: int,
                         out_png: str | Path) -> Path:
    """One row per marker: region, similarity, thresholded, opened, centroid (thesis Fig. 3.10)."""
    from matplotlib.figure import Figure

    view = read_frame(video, frame_index)
    footprint = disk_footprint(setup.opening_radius)
    figure = Figure(figsize=(13, 2.7 * len(setup.markers)))
    axes = figure.subplots(len(setup.markers), 5, squeeze=False)
    for row, marker in zip(axes, setup.markers):
        x0, y0, x1, y1 = marker.roi
        found = detect_marker(view.crop(x0, y0, x1, y1), (x0, y0), marker, footprint, None)
        cx, cy = (found.x_px, found.y_px) if found.valid else (0.5 * (x0 + x1), 0.5 * (y0 + y1))
        half = int(4 * marker.radius_px + 10)
        box = (max(int(cx) - half, x0), max(int(cy) - half, y0), min(int(cx) + half, x1),
               min(int(cy) + half, y1))
        rgb = view.crop(*box)
        score = similarity(rgb, marker.colour)
        mask = score > marker.threshold
        opened = ndimage.binary_opening(mask, structure=footprint)
        extent = (box[0] - 0.5, box[2] - 0.5, box[3] - 0.5, box[1] - 0.5)
        panels = [(rgb, None, f"{marker.name}: region"), (score, "gray", "colour similarity"),
                  (mask, "gray", f"> threshold {marker.threshold:.3f}"),
                  (opened, "gray", f"opened (disk r={setup.opening_radius})"),
                  (rgb, None, "centroid" if found.valid else f"lost: {found.reason}")]
        for axis, (image, cmap, title) in zip(row, panels):
            axis.imshow(image, cmap=cmap, extent=extent, interpolation="nearest")
            axis.set_title(title, fontsize=9)
            axis.tick_params(labelsize=7)
        if found.valid:
            row[4].plot([cx], [cy], "+", color="white", markersize=14, markeredgewidth=2)
            row[4].plot([cx], [cy], "+", color="black", markersize=8, markeredgewidth=1)
    figure.suptitle(f"{Path(video).name}, frame {frame_index}: marker detection steps")
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    out_png = Path(out_png)
    figure.savefig(out_png, dpi=90)
    return out_png


def plot_synchronisation(result: SyncResult, out_png: str, *, window: int = 60) -> str:
    """Correlation against coarse lag for each phase, and the peak per phase (thesis Fig. 3.8).

    Parameters
    ----------
    result : SyncResult
    out_png : str
    window : int
        Coarse lags either side of the peak in the zoomed inset.
    """
    from matplotlib.figure import Figure

    figure = Figure(figsize=(15, 4.5))
    left, middle, right = figure.subplots(1, 3)
    phases = np.mod(result.shifts, result.decimation)
    lags = np.floor_divide(result.shifts, result.decimation)
    for p in range(result.decimation):
        pick = phases == p
        style = dict(linewidth=1.2 if p == result.phase else 0.5,
                     color="black" if p == result.phase else None)
        left.plot(lags[pick], result.correlation[pick], **style)
        near = pick & (np.abs(lags - result.lag) <= window)
        middle.plot(lags[near], result.correlation[near], label=f"phase {p}", **style)
    left.set(title="normalised cross-correlation, all phases", xlabel="lag [camera frames]",
             ylabel="rho")
    middle.set(title=f"around the peak (lag {result.lag})", xlabel="lag [camera frames]")
    middle.legend(fontsize=7, ncol=2)
    right.bar(np.arange(result.decimation), result.peaks_per_phase(), color="gray")
    right.bar([result.phase], [result.confidence], color="black")
    right.set(title=f"peak per start phase: shift = {result.lag} x {result.decimation} + "
                    f"{result.phase} = {result.shift}", xlabel="phase [fine samples]",
              ylabel="peak rho", ylim=(min(0.0, np.nanmin(result.peaks_per_phase())), 1.0))
    figure.tight_layout()
    figure.set_layout_engine(None)  # laid out: savefig draws once
    figure.savefig(out_png, dpi=110)
    return str(out_png)


__all__ = ["plot_detection_steps", "plot_synchronisation"]
