"""Step 3 of the thesis' marker detection (section 3.3.1), "maximise the saturation", measured.

The thesis maps the grey-scale similarity image ``s`` (step 2) so that marker-coloured areas stay
white and all others are darkened as much as possible, then thresholds it (step 4). Done with one
map for every frame, e.g. :func:`saturate`

.. math:: s' = \\mathrm{clip}\\left(\\frac{s - s_0}{1 - s_0}, 0, 1\\right),

the map is increasing on ``s > s_0``, so ``s' > t'`` selects exactly the pixels ``s > t`` with
``t = s_0 + t' (1 - s_0)``: the binary image, and so steps 5-6 and the positions, do not change;
:mod:`panto.video_sync.tracking` therefore thresholds ``s`` directly with the equivalent
threshold. A stretch computed per frame (MATLAB's ``imadjust`` with per-image limits) is a
different thing: an adaptive threshold that moves with each frame's content.
:func:`compare_saturation` counts, on a video, the mask pixels and blob centroids that either
variant changes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from panto.video_sync.track_file import TrackerSetup
from panto.video_sync.tracking import disk_footprint, squared_distance
from panto.video_sync.video_io import read_frame_views


def saturate(similarity: np.ndarray, floor: float) -> np.ndarray:
    """Step 3 with one map for all frames: ``clip((s - floor) / (1 - floor), 0, 1)``."""
    if not 0.0 <= floor < 1.0:
        raise ValueError(f"saturation floor must be in [0, 1), got {floor!r}")
    return np.clip((np.asarray(similarity, float) - floor) / (1.0 - floor), 0.0, 1.0)


def stretch_per_frame(similarity: np.ndarray, low: float = 1.0, high: float = 99.0) -> np.ndarray:
    """Step 3 as a per-image contrast stretch between the `low` and `high` percentiles."""
    s = np.asarray(similarity, float)
    lo, hi = np.percentile(s, [low, high])
    return np.clip((s - lo) / max(hi - lo, 1e-12), 0.0, 1.0)


@dataclass(frozen=True)
class SaturationComparison:
    """Differences made by step 3 on a video (all markers, all frames).

    Attributes
    ----------
    n_pixels : int
        Region pixels compared.
    fixed_changed, stretched_changed : int
        Mask pixels that differ from ``s > threshold`` with the fixed map (threshold mapped) and
        with a per-frame stretch (the same threshold applied to the stretched image).
    fixed_shift_px, stretched_shift_px : float
        Largest shift of the opened mask's centroid [px] (NaN where a mask is empty).
    """

    n_pixels: int
    fixed_changed: int
    stretched_changed: int
    fixed_shift_px: float
    stretched_shift_px: float


def _centroid(mask: np.ndarray, footprint: np.ndarray) -> np.ndarray:
    opened = ndimage.binary_opening(mask, structure=footprint)
    if not opened.any():
        return np.full(2, np.nan)
    return np.array(ndimage.center_of_mass(opened))


def compare_saturation(path: str | Path, setup: TrackerSetup, *, floor: float = 0.5,
                       max_frames: int | None = None) -> SaturationComparison:
    """Threshold every marker region of `path` without step 3, with :func:`saturate` (threshold
    mapped) and with :func:`stretch_per_frame`; count what changes."""
    footprint = disk_footprint(2)
    scale = np.float32(255.0 * math.sqrt(3.0))
    n_pixels = fixed = stretched = 0
    fixed_shift = stretched_shift = 0.0
    for count, view in enumerate(read_frame_views(path)):
        if max_frames is not None and count >= max_frames:
            break
        for marker in setup.markers:
            s = 1.0 - np.sqrt(squared_distance(view.crop_channels(*marker.roi),
                                               marker.colour)) / scale
            base = s > marker.threshold
            mapped = saturate(s, floor) > (marker.threshold - floor) / (1.0 - floor)
            adaptive = stretch_per_frame(s) > marker.threshold
            n_pixels += base.size
            fixed += int(np.count_nonzero(base != mapped))
            stretched += int(np.count_nonzero(base != adaptive))
            centre = _centroid(base, footprint)
            fixed_shift = np.nanmax([fixed_shift, *np.abs(_centroid(mapped, footprint) - centre)])
            stretched_shift = np.nanmax([stretched_shift,
                                         *np.abs(_centroid(adaptive, footprint) - centre)])
    return SaturationComparison(n_pixels, fixed, stretched, float(fixed_shift),
                                float(stretched_shift))
