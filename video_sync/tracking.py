"""Marker tracking and LED read-out in a video (thesis section 3.3.1, done right).

Per marker and frame (thesis section 3.3.1, steps 1-6):

1. colour similarity to the marker's reference colour ``c_ref`` (RGB, 0..255) inside a window
   that follows the marker (the prediction from the last two positions, clipped to the marker's
   region of interest):

   .. math:: s(p) = 1 - \\frac{\\lVert c(p) - c_\\mathrm{ref} \\rVert_2}{255 \\sqrt{3}} \\in [0, 1]

2. the binary image ``s > threshold`` (the user threshold);
3. morphological opening with the disk footprint of :func:`disk_footprint` (radius 2 px:
   the 13 pixels with ``i^2 + j^2 <= 4``), which removes every blob too small to hold it;
4. of the connected components (8-connected) that remain, the one nearest to the prediction;
5. its sub-pixel centre: the centroid weighted with the covered fraction of each pixel,
   estimated from the colour distance ``d = ||c - c_ref||`` as
   ``alpha = clip((d_bg - d) / (d_bg - d_fg), 0, 1)`` with ``d_fg`` the median distance inside the
   blob and ``d_bg`` the median on a ring around it (an anti-aliased edge pixel is a mix of the
   two colours, so this is an unbiased estimate of the area centroid);
6. pixel -> metres with the marker's scale ``(s_x, s_y)`` [mm/px] and offset ``(x_0, y_0)`` [m]
   (the absolute position of pixel (0, 0) in the marker's plane; heights up, rows down):
   ``x = x_0 + 10^-3 s_x c``, ``y = y_0 - 10^-3 s_y r``.

A marker is *lost* in a frame (NaN, ``valid = 0``) when no blob remains, when the blob's area is
not that of the marker's disc (0.35 .. 2 times ``pi r^2``), when its bounding box is not round
(aspect 0.5 .. 2, fill 0.5 .. 1), when it touches the border of the marker's region (it is
leaving it) or when it lies further than ``max_step_px`` from the prediction; a false detection is
never reported. After a loss the window grows (doubling per lost frame, up to the whole region)
until the marker is found again.

The LED: per frame the relative red excess of its region,
``e = mean(R - (G + B)/2) / mean((G + B)/2)`` (a global lighting gain cancels); the on/off
threshold is the two-cluster (isodata) threshold of all frames' levels unless the set-up fixes
it. Quality: per frame ``q_k = min(1, |e_k - e_thr| / ((m_1 - m_0)/2))``; overall
``Q = clip(1 - 3 (sigma_0 + sigma_1) / (m_1 - m_0), 0, 1)`` (1: point clusters; 0: their 3-sigma
bands touch), where ``m_i, sigma_i`` are the clusters' means and spreads.

Speed: :func:`track_video` cuts the video at keyframes into segments and tracks them in parallel
processes. A segment's first frame finds each marker by the whole-region search that also follows
a loss, and a marker's window holds its blob and the centroid's ring whatever the window's size,
so the positions equal those of one serial pass. Each window is converted from YUV and compared
with the reference colour element by element in float32 (:meth:`FrameView.crop_channels`), so a
pixel's distance does not depend on the window it is cut with.
"""
from __future__ import annotations

import math
import os
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import ndimage

from panto.video_sync.track_file import (SETUP_FORMAT, TRACK_FORMAT, LedSetup, MarkerSetup, MarkerTrack,
                                   SetupError, TrackerSetup, TrackResult)
from panto.video_sync.video_io import FrameView, Segment, read_frame_views, split_at_keyframes

__all__ = ["SETUP_FORMAT", "TRACK_FORMAT", "Detection", "LedSetup", "MarkerSetup", "MarkerTrack",
           "MarkerTracker", "SetupError", "TrackResult", "TrackerSetup", "classify_led",
           "colour_distance", "detect_marker", "disk_footprint", "isodata_threshold",
           "read_led_level", "similarity", "squared_distance", "SegmentTrack", "track_segment",
           "track_video"]


def disk_footprint(radius: int = 2) -> np.ndarray:
    """The disk structuring element: the offsets (i, j) with ``i^2 + j^2 <= radius^2``.

    For radius 2 these are the 13 pixels of a 5 x 5 square without the 12 pixels at
    ``|i| + |j| >= 3``::

        . . X . .
        . X X X .
        X X X X X
        . X X X .
        . . X . .

    (OpenCV's 5 x 5 ``MORPH_ELLIPSE`` is a different shape: it also holds the 8 pixels
    ``(+-1, +-2)``, ``(+-2, +-1)``, 21 in all.)
    """
    radius = int(radius)
    if radius < 0:
        raise ValueError(f"disk radius {radius} must be >= 0")
    offsets = np.arange(-radius, radius + 1)
    return offsets[:, None] ** 2 + offsets[None, :] ** 2 <= radius ** 2


_EIGHT = np.ones((3, 3), dtype=bool)
_AREA_RANGE = (0.35, 2.0)
_ASPECT_RANGE = (0.5, 2.0)
_FILL_RANGE = (0.5, 1.0)


def similarity(rgb: np.ndarray, colour: tuple[float, float, float]) -> np.ndarray:
    """Colour similarity ``1 - ||c - c_ref|| / (255 sqrt 3)`` of every pixel (float32)."""
    return 1.0 - colour_distance(rgb, colour) / np.float32(255.0 * math.sqrt(3.0))


def colour_distance(rgb: np.ndarray, colour: tuple[float, float, float]) -> np.ndarray:
    """Euclidean RGB distance ``||c - c_ref||`` of every pixel (float32, 0 .. 441.7)."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return np.sqrt(squared_distance(tuple(rgb[..., k] for k in range(3)), colour))


def squared_distance(channels: tuple[np.ndarray, np.ndarray, np.ndarray],
                     colour: tuple[float, float, float]) -> np.ndarray:
    """``||c - c_ref||^2`` from the R, G, B planes (float32, element by element)."""
    red, green, blue = (np.subtract(plane, np.float32(level), dtype=np.float32)
                        for plane, level in zip(channels, colour))
    red *= red
    green *= green
    blue *= blue
    red += green
    red += blue
    return red


def isodata_threshold(values: np.ndarray, *, iterations: int = 100) -> float:
    """Two-cluster threshold: the midpoint of the two class means it separates (Ridler-Calvard).

    Iterates ``t <- (mean(v <= t) + mean(v > t)) / 2`` from the mean until it stops changing.
    """
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        raise ValueError("isodata threshold of no values")
    threshold = float(values.mean())
    for _ in range(iterations):
        low, high = values[values <= threshold], values[values > threshold]
        if low.size == 0 or high.size == 0:
            return threshold
        new = 0.5 * (low.mean() + high.mean())
        if abs(new - threshold) < 1e-9 * (1 + abs(threshold)):
            break
        threshold = float(new)
    return threshold


@dataclass(frozen=True)
class Detection:
    """One marker in one frame (full-frame pixel coordinates; NaN when lost)."""

    x_px: float
    y_px: float
    valid: bool
    reason: str = ""


_LOST = float("nan")


def _lost(reason: str) -> Detection:
    return Detection(_LOST, _LOST, False, reason)


def detect_marker(rgb: np.ndarray, origin: tuple[int, int], marker: MarkerSetup,
                  footprint: np.ndarray, prediction: tuple[float, float] | None,
                  *, touches_region: tuple[bool, bool, bool, bool] = (True,) * 4) -> Detection:
    """Find `marker` in the window `rgb` whose pixel (0, 0) is frame pixel `origin` = (x, y).

    Parameters
    ----------
    rgb : numpy.ndarray, shape (h, w, 3)
    origin : tuple of int
    marker : MarkerSetup
    footprint : numpy.ndarray of bool
        Structuring element of the opening.
    prediction : tuple of float or None
        Expected (x, y) in frame pixels; None: search by size alone (no step check).
    touches_region : tuple of bool
        Whether the window's left, top, right, bottom edges are the region's edges (a blob
        touching them is leaving the region: lost).
    """
    rgb = np.asarray(rgb, dtype=np.float32)
    squared = squared_distance(tuple(rgb[..., k] for k in range(3)), marker.colour)
    return _detect(squared, origin, marker, footprint, prediction, touches_region)


def _detect(squared: np.ndarray, origin: tuple[int, int], marker: MarkerSetup,
            footprint: np.ndarray, prediction: tuple[float, float] | None,
            touches_region: tuple[bool, bool, bool, bool]) -> Detection:
    """:func:`detect_marker` on the squared colour distances of the window.

    The opening and labelling run on the bounding box of the thresholded pixels (plus a margin
    of the footprint's radius), which gives the same result as on the whole window and is much
    cheaper when the window holds little more than the marker.
    """
    limit = (1.0 - marker.threshold) * 255.0 * math.sqrt(3.0)
    mask = squared < np.float32(limit * limit)
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return _lost("no blob")
    columns = np.flatnonzero(mask.any(axis=0))
    pad = footprint.shape[0] // 2 + 1
    r0, c0 = max(rows[0] - pad, 0), max(columns[0] - pad, 0)
    r1, c1 = min(rows[-1] + pad + 1, mask.shape[0]), min(columns[-1] + pad + 1, mask.shape[1])
    opened = ndimage.binary_opening(mask[r0:r1, c0:c1], structure=footprint)
    labels, count = ndimage.label(opened, structure=_EIGHT)
    if count == 0:
        return _lost("no blob")
    number, (rows_, columns_), area = _choose_blob(labels, (origin[0] + c0, origin[1] + r0),
                                                   marker, prediction)
    region = (slice(rows_.start + r0, rows_.stop + r0), slice(columns_.start + c0,
                                                              columns_.stop + c0))
    problem = _shape_problem(region, area, math.pi * marker.radius_px ** 2, mask.shape,
                             touches_region)
    if problem:
        return _lost(problem)
    x, y = _weighted_centroid(squared, labels[rows_, columns_] == number, region)
    x, y = x + origin[0], y + origin[1]
    if prediction is not None and math.hypot(x - prediction[0], y - prediction[1]) \
            > marker.max_step_px:
        return _lost("jump beyond max_step_px")
    return Detection(x, y, True)


def _choose_blob(labels: np.ndarray, origin: tuple[int, int], marker: MarkerSetup,
                 prediction: tuple[float, float] | None) -> tuple[int, tuple[slice, slice], int]:
    """The component nearest the prediction, or (no prediction) the one of the marker's size."""
    expected = math.pi * marker.radius_px ** 2
    best, best_score = None, math.inf
    for number, region in enumerate(ndimage.find_objects(labels), start=1):
        if region is None:
            continue
        area = int(np.count_nonzero(labels[region] == number))
        rows, columns = region
        centre = (origin[0] + 0.5 * (columns.start + columns.stop - 1),
                  origin[1] + 0.5 * (rows.start + rows.stop - 1))
        if prediction is None:
            score = abs(math.log(max(area, 1) / expected))
        else:
            score = math.hypot(centre[0] - prediction[0], centre[1] - prediction[1])
        if score < best_score:
            best, best_score = (number, region, area), score
    return best


def _shape_problem(region: tuple[slice, slice], area: int, expected: float,
                   shape: tuple[int, int], touches_region: tuple[bool, bool, bool, bool]) -> str:
    rows, columns = region
    height, width = rows.stop - rows.start, columns.stop - columns.start
    if not _AREA_RANGE[0] <= area / expected <= _AREA_RANGE[1]:
        return f"blob area {area} px, expected {expected:.0f}"
    if not _ASPECT_RANGE[0] <= width / height <= _ASPECT_RANGE[1] \
            or not _FILL_RANGE[0] <= area / (width * height) <= _FILL_RANGE[1]:
        return "blob not round"
    edges = (columns.start == 0, rows.start == 0, columns.stop == shape[1], rows.stop == shape[0])
    if any(edge for edge in edges):
        return "blob at the region's border" if any(
            e and t for e, t in zip(edges, touches_region)) else "blob at the window's border"
    return ""


def _weighted_centroid(squared: np.ndarray, blob: np.ndarray, region: tuple[slice, slice]
                       ) -> tuple[float, float]:
    """Coverage-weighted centroid (x, y) in window pixels (see the module notes, step 5).

    `blob` marks the chosen component inside `region` (its bounding box in the window). The
    weights are taken within 2 px of the blob's equivalent disc (radius ``sqrt(area/pi)`` about
    its area centroid); the background level on the ring 3 .. 5 px outside it. Everything is
    computed on the box ``region`` + 6 px (clipped to the window).
    """
    rows, columns = region
    pad = 6
    r0, c0 = max(rows.start - pad, 0), max(columns.start - pad, 0)
    r1, c1 = min(rows.stop + pad, squared.shape[0]), min(columns.stop + pad, squared.shape[1])
    distance = np.sqrt(squared[r0:r1, c0:c1])
    inside = np.zeros(distance.shape, dtype=bool)
    inside[rows.start - r0:rows.stop - r0, columns.start - c0:columns.stop - c0] = blob
    yy, xx = np.nonzero(inside)
    radius = math.sqrt(yy.size / math.pi)
    radial = np.hypot(np.arange(distance.shape[1]) - float(xx.sum()) / xx.size,
                      (np.arange(distance.shape[0]) - float(yy.sum()) / yy.size)[:, None])
    near = radial <= radius + 2.0
    ring = (radial >= radius + 3.0) & (radial <= radius + 5.0)
    d_fg = _median(distance[inside])
    d_bg = _median(distance[ring]) if ring.any() else float(distance[~near].max())
    if d_bg - d_fg <= 1e-6:
        weights = inside.astype(np.float32)
    else:
        weights = np.clip((d_bg - distance) / (d_bg - d_fg), 0.0, 1.0) * near
    total = float(weights.sum())
    return (float((weights.sum(axis=0) * np.arange(distance.shape[1])).sum() / total + c0),
            float((weights.sum(axis=1) * np.arange(distance.shape[0])).sum() / total + r0))


def _median(values: np.ndarray) -> float:
    """The median of a non-empty 1-D array (mean of the two middle values for an even count)."""
    half = values.size // 2
    if values.size % 2:
        return float(np.partition(values, half)[half])
    low, high = np.partition(values, [half - 1, half])[half - 1:half + 1]
    return 0.5 * (float(low) + float(high))


class MarkerTracker:
    """Follows one marker from frame to frame (window, prediction, loss, re-acquisition)."""

    def __init__(self, marker: MarkerSetup, footprint: np.ndarray) -> None:
        self.marker = marker
        self.footprint = footprint
        self._history: list[tuple[float, float]] = []  # the last two valid positions
        self._lost = 0
        self._ever_found = False

    def _window(self) -> tuple[tuple[int, int, int, int], tuple[float, float] | None]:
        x0, y0, x1, y1 = self.marker.roi
        if not self._history:
            return (x0, y0, x1, y1), None
        last = self._history[-1]
        velocity = ((last[0] - self._history[-2][0], last[1] - self._history[-2][1])
                    if len(self._history) == 2 and self._lost == 0 else (0.0, 0.0))
        prediction = (last[0] + velocity[0], last[1] + velocity[1])
        # a blob within max_step of the prediction, with the centroid's background ring
        half = (self.marker.max_step_px + self.marker.radius_px + 8) * 2 ** min(self._lost, 8)
        window = (max(x0, int(prediction[0] - half)), max(y0, int(prediction[1] - half)),
                  min(x1, int(prediction[0] + half) + 1), min(y1, int(prediction[1] + half) + 1))
        return window, (prediction if self._lost == 0 else None)

    def step(self, view: FrameView) -> Detection:
        """Detect the marker in one frame and update the state."""
        window, prediction = self._window()
        x0, y0, x1, y1 = window
        roi = self.marker.roi
        touches = (x0 == roi[0], y0 == roi[1], x1 == roi[2], y1 == roi[3])
        squared = squared_distance(view.crop_channels(x0, y0, x1, y1), self.marker.colour)
        detection = _detect(squared, (x0, y0), self.marker, self.footprint, prediction, touches)
        if detection.valid:
            self._history = (self._history + [(detection.x_px, detection.y_px)])[-2:]
            if self._lost:
                self._history = self._history[-1:]
            self._lost = 0
        elif self._history:
            self._lost += 1
        return detection


def read_led_level(view: FrameView, region: tuple[int, int, int, int]) -> float:
    """Relative red excess ``mean(R - (G+B)/2) / mean((G+B)/2)`` of the LED's region."""
    red, green, blue = view.crop_channels(*region)
    green_blue = 0.5 * (green + blue)
    return float((red - green_blue).mean() / max(float(green_blue.mean()), 1.0))


def classify_led(levels: np.ndarray, threshold: float | None = None
                 ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """LED bits, per-frame quality, threshold and overall quality from the frames' levels."""
    levels = np.asarray(levels, dtype=float)
    if levels.size == 0:
        return np.zeros(0, int), np.zeros(0), math.nan, 0.0
    threshold = isodata_threshold(levels) if threshold is None else float(threshold)
    bits = (levels > threshold).astype(int)
    if bits.min() == bits.max():  # one cluster: the LED never changed (or is not there)
        return bits, np.zeros(levels.size), threshold, 0.0
    low, high = levels[bits == 0], levels[bits == 1]
    gap = high.mean() - low.mean()
    quality = np.clip(np.abs(levels - threshold) / (0.5 * gap), 0.0, 1.0)
    overall = float(np.clip(1.0 - 3.0 * (low.std() + high.std()) / gap, 0.0, 1.0))
    return bits, quality, threshold, overall


def track_video(path: str | Path, setup: TrackerSetup, *, workers: int | None = None,
                executor: Executor | None = None, threads: bool | str = False,
                progress: Callable[[str], None] | None = None) -> TrackResult:
    """Track every marker of `setup` and read the LED in every frame of a video (streaming).

    The video is cut at keyframes into segments (:func:`panto.video_sync.video_io.split_at_keyframes`,
    about four per worker, so a busy core does not hold up the rest), the segments are tracked in
    parallel and joined in order. The result equals a serial pass (see the module notes).

    Parameters
    ----------
    path : str or pathlib.Path
        Video file.
    setup : TrackerSetup
    workers : int, optional
        Processes of the local pool; default: the CPUs this process may run on. 1 (and no
        `executor`): one serial pass in this process.
    executor : concurrent.futures.Executor, optional
        Runs the segments instead of a local process pool (e.g. a Dask client's executor).
    threads : bool or str
        FFmpeg's decoder threads (see :func:`panto.video_sync.video_io.read_frame_views`).
    progress : callable, optional
        Receives a line every 500 frames (serial) or per finished segment (parallel).

    Returns
    -------
    TrackResult
        Per-frame positions (pixels and metres), validity, LED bits and quality.

    Raises
    ------
    VideoError
        Missing, unreadable or corrupt video.
    """
    path = Path(path)
    workers = _usable_cpus() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers = {workers}: need at least 1")
    segments = (split_at_keyframes(path, _SEGMENTS_PER_WORKER * workers)
                if workers > 1 or executor is not None else [])
    if len(segments) <= 1:
        parts = [track_segment(path, setup, None, threads, progress)]
    else:
        parts = _track_in_parallel(path, setup, segments, workers, executor, threads, progress)
    return _assemble(path, setup, parts)


_SEGMENTS_PER_WORKER = 4


def _usable_cpus() -> int:
    """The CPUs this process may run on (all of them where the system cannot say)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


@dataclass(frozen=True)
class SegmentTrack:
    """Raw per-frame results of one segment: frame, time, ``(x_px, y_px, valid)`` per marker."""

    frame: np.ndarray
    time: np.ndarray
    positions: dict[str, np.ndarray]
    levels: np.ndarray


def track_segment(path: str | Path, setup: TrackerSetup, segment: Segment | None = None,
                  threads: bool | str = False, progress: Callable[[str], None] | None = None
                  ) -> SegmentTrack:
    """Track the frames of one segment of a video (None: the whole file), trackers fresh."""
    footprint = disk_footprint(setup.opening_radius)
    trackers = [MarkerTracker(m, footprint) for m in setup.markers]
    frames, times, levels, rows = [], [], [], []
    for view in read_frame_views(path, threads=threads, segment=segment):
        frames.append(view.index)
        times.append(view.time)
        for tracker in trackers:
            found = tracker.step(view)
            rows.append((found.x_px, found.y_px, found.valid))
        if setup.led is not None:
            levels.append(read_led_level(view, setup.led.region))
        if progress and (view.index + 1) % 500 == 0:
            progress(f"tracked {view.index + 1} frames")
    table = np.array(rows, dtype=float).reshape(len(frames), len(trackers), 3)
    return SegmentTrack(np.array(frames, int), np.array(times, float),
                        {m.name: table[:, k] for k, m in enumerate(setup.markers)},
                        np.array(levels, float))


def _track_in_parallel(path: Path, setup: TrackerSetup, segments: list[Segment], workers: int,
                       executor: Executor | None, threads: bool | str,
                       progress: Callable[[str], None] | None) -> list[SegmentTrack]:
    pool = executor or ProcessPoolExecutor(max_workers=min(workers, len(segments)))
    try:
        futures = {pool.submit(track_segment, path, setup, segment, threads): segment
                   for segment in segments}
        done, total = 0, sum(s.frame_count for s in segments)
        for future in as_completed(futures):
            future.result()
            done += futures[future].frame_count
            if progress:
                progress(f"tracked {done}/{total} frames ({len(segments)} segments)")
        return [future.result() for future in futures]
    finally:
        if executor is None:
            pool.shutdown(cancel_futures=True)


def _assemble(path: Path, setup: TrackerSetup, parts: list[SegmentTrack]) -> TrackResult:
    """Join the segments' rows (in file order) into a :class:`TrackResult`."""
    frames = np.concatenate([p.frame for p in parts])
    times = np.concatenate([p.time for p in parts])
    tracks = {}
    for marker in setup.markers:
        table = np.concatenate([p.positions[marker.name] for p in parts])
        tracks[marker.name] = MarkerTrack.from_pixels(table[:, 0], table[:, 1],
                                                      table[:, 2].astype(bool), marker)
    if setup.led is None:
        levels, bits, quality = np.full(frames.size, np.nan), np.zeros(frames.size, int), \
            np.zeros(frames.size)
        threshold, overall = math.nan, 0.0
    else:
        levels = np.concatenate([p.levels for p in parts])
        bits, quality, threshold, overall = classify_led(levels, setup.led.threshold)
    return TrackResult(path, _fps(times), setup, frames, times, tracks, bits, quality, levels,
                       threshold, overall)


def _fps(times: np.ndarray) -> float:
    if len(times) < 2:
        return 50.0
    return float(round(1.0 / float(np.median(np.diff(times))), 6))
