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
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
from scipy import ndimage

from video_sync.video_io import FrameView, read_frame_views

TRACK_FORMAT = "panto-video-track"
SETUP_FORMAT = "panto-video-setup"


class SetupError(ValueError):
    """A tracker set-up (file) is incomplete or wrong; names the file and the field."""


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


def _tuple(value: Any, length: int, name: str, where: str) -> tuple:
    try:
        result = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        result = ()
    if len(result) != length:
        raise SetupError(f"{where}: field {name!r} must be {length} numbers, got {value!r}")
    return result


@dataclass(frozen=True)
class MarkerSetup:
    """How to find one marker.

    Attributes
    ----------
    name : str
    roi : tuple of int
        Region ``(x0, y0, x1, y1)`` [px, end exclusive] the marker must stay inside.
    colour : tuple of float
        Reference colour RGB (0..255), the mean of a patch inside the marker.
    threshold : float
        Similarity threshold in [0, 1]: a pixel belongs to the marker if ``s > threshold``.
    mm_per_px : tuple of float
        Scale (horizontal, vertical) [mm/px] in the marker's plane.
    offset : tuple of float
        Absolute position (x, y) [m] of pixel (0, 0) in the marker's plane (y up).
    radius_px : float
        Expected disc radius [px] (area check).
    max_step_px : float
        Largest plausible distance from the prediction to the next frame's position [px].
    """

    name: str
    roi: tuple[int, int, int, int]
    colour: tuple[float, float, float]
    threshold: float
    mm_per_px: tuple[float, float]
    offset: tuple[float, float]
    radius_px: float = 10.0
    max_step_px: float = 40.0

    def to_metres(self, x_px: np.ndarray, y_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Absolute position [m]: ``x = x_0 + 1e-3 s_x c``, ``y = y_0 - 1e-3 s_y r``."""
        return (self.offset[0] + 1e-3 * self.mm_per_px[0] * np.asarray(x_px, float),
                self.offset[1] - 1e-3 * self.mm_per_px[1] * np.asarray(y_px, float))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str) -> "MarkerSetup":
        _require(data, [f.name for f in fields(cls) if f.name not in ("radius_px", "max_step_px")],
                 where)
        marker = cls(str(data["name"]), tuple(int(v) for v in _tuple(data["roi"], 4, "roi", where)),
                     _tuple(data["colour"], 3, "colour", where), float(data["threshold"]),
                     _tuple(data["mm_per_px"], 2, "mm_per_px", where),
                     _tuple(data["offset"], 2, "offset", where),
                     float(data.get("radius_px", 10.0)), float(data.get("max_step_px", 40.0)))
        x0, y0, x1, y1 = marker.roi
        if x1 <= x0 or y1 <= y0:
            raise SetupError(f"{where}: field 'roi' {list(marker.roi)} is empty")
        if not 0.0 < marker.threshold < 1.0:
            raise SetupError(f"{where}: field 'threshold' {marker.threshold} not in (0, 1)")
        return marker


@dataclass(frozen=True)
class LedSetup:
    """The LED's region ``(x0, y0, x1, y1)`` [px] and an optional fixed level threshold."""

    region: tuple[int, int, int, int]
    threshold: float | None = None

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], where: str) -> "LedSetup":
        _require(data, ["region"], where)
        threshold = data.get("threshold")
        return cls(tuple(int(v) for v in _tuple(data["region"], 4, "region", where)),
                   None if threshold is None else float(threshold))


def _require(data: Any, names: list[str], where: str) -> None:
    if not isinstance(data, Mapping):
        raise SetupError(f"{where}: expected an object, got {type(data).__name__}")
    missing = [n for n in names if n not in data]
    if missing:
        raise SetupError(f"{where}: field(s) {missing} missing")


@dataclass(frozen=True)
class TrackerSetup:
    """Markers to track, the LED to read, and the opening's disk radius [px]."""

    markers: tuple[MarkerSetup, ...]
    led: LedSetup | None = None
    opening_radius: int = 2

    def __post_init__(self) -> None:
        names = [m.name for m in self.markers]
        if len(set(names)) != len(names):
            raise SetupError(f"tracker set-up: duplicated marker names {names}")

    def to_dict(self) -> dict[str, Any]:
        return {"format": SETUP_FORMAT, "version": 1, **asdict(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "tracker set-up"
                  ) -> "TrackerSetup":
        """Rebuild from :meth:`to_dict`; a missing or malformed field raises :class:`SetupError`."""
        _require(data, ["markers"], where)
        if not isinstance(data["markers"], list) or not data["markers"]:
            raise SetupError(f"{where}: field 'markers' must be a non-empty list")
        markers = tuple(MarkerSetup.from_dict(m, f"{where}: markers[{i}]")
                        for i, m in enumerate(data["markers"]))
        led = data.get("led")
        return cls(markers, None if led is None else LedSetup.from_dict(led, f"{where}: led"),
                   int(data.get("opening_radius", 2)))

    def save(self, path: str | Path) -> Path:
        """Write as JSON."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "TrackerSetup":
        """Read a JSON set-up file; errors name the file and the field."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except OSError as error:
            raise SetupError(f"{path}: cannot read the set-up file ({error})") from None
        except json.JSONDecodeError as error:
            raise SetupError(f"{path}: not valid JSON ({error})") from None
        return cls.from_dict(data, where=str(path))

    def marker(self, name: str) -> MarkerSetup:
        for marker in self.markers:
            if marker.name == name:
                return marker
        raise KeyError(f"no marker {name!r} in the set-up")

_EIGHT = np.ones((3, 3), dtype=bool)
_AREA_RANGE = (0.35, 2.0)
_ASPECT_RANGE = (0.5, 2.0)
_FILL_RANGE = (0.5, 1.0)


def similarity(rgb: np.ndarray, colour: tuple[float, float, float]) -> np.ndarray:
    """Colour similarity ``1 - ||c - c_ref|| / (255 sqrt 3)`` of every pixel (float32)."""
    return 1.0 - colour_distance(rgb, colour) / np.float32(255.0 * math.sqrt(3.0))


def colour_distance(rgb: np.ndarray, colour: tuple[float, float, float]) -> np.ndarray:
    """Euclidean RGB distance ``||c - c_ref||`` of every pixel (float32, 0 .. 441.7)."""
    difference = np.asarray(rgb, dtype=np.float32) - np.asarray(colour, dtype=np.float32)
    return np.sqrt(np.einsum("...k,...k->...", difference, difference))


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

    Notes
    -----
    The opening and labelling run on the bounding box of the thresholded pixels (plus a margin
    of the footprint's radius), which gives the same result as on the whole window and is much
    cheaper when the window holds little more than the marker.
    """
    distance = colour_distance(rgb, marker.colour)
    limit = (1.0 - marker.threshold) * 255.0 * math.sqrt(3.0)
    mask = distance < limit
    rows, columns = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return _lost("no blob")
    pad = footprint.shape[0] // 2 + 1
    r0, c0 = max(rows[0] - pad, 0), max(columns[0] - pad, 0)
    r1, c1 = min(rows[-1] + pad + 1, mask.shape[0]), min(columns[-1] + pad + 1, mask.shape[1])
    opened = np.zeros_like(mask)
    opened[r0:r1, c0:c1] = ndimage.binary_opening(mask[r0:r1, c0:c1], structure=footprint)
    labels, count = ndimage.label(opened[r0:r1, c0:c1], structure=_EIGHT)
    if count == 0:
        return _lost("no blob")
    full_labels = np.zeros(mask.shape, dtype=labels.dtype)
    full_labels[r0:r1, c0:c1] = labels
    number, region, area = _choose_blob(full_labels, origin, marker, prediction)
    expected = math.pi * marker.radius_px ** 2
    problem = _shape_problem(region, area, expected, mask.shape, touches_region)
    if problem:
        return _lost(problem)
    x, y = _weighted_centroid(distance, full_labels == number, region)
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


def _weighted_centroid(distance: np.ndarray, blob: np.ndarray, region: tuple[slice, slice]
                       ) -> tuple[float, float]:
    """Coverage-weighted centroid (x, y) in window pixels (see the module notes, step 5).

    The weights are taken within 2 px of the blob's equivalent disc (radius ``sqrt(area/pi)``
    about its area centroid); the background level on the ring 3 .. 5 px outside it.
    """
    rows, columns = region
    pad = 6
    r0, c0 = max(rows.start - pad, 0), max(columns.start - pad, 0)
    r1, c1 = min(rows.stop + pad, blob.shape[0]), min(columns.stop + pad, blob.shape[1])
    blob, distance = blob[r0:r1, c0:c1], distance[r0:r1, c0:c1]
    yy, xx = np.nonzero(blob)
    radius = math.sqrt(yy.size / math.pi)
    grid_y, grid_x = np.ogrid[0:blob.shape[0], 0:blob.shape[1]]
    radial = np.hypot(grid_x - xx.mean(), grid_y - yy.mean())
    near = radial <= radius + 2.0
    ring = (radial >= radius + 3.0) & (radial <= radius + 5.0)
    d_fg = float(np.median(distance[blob]))
    d_bg = float(np.median(distance[ring])) if ring.any() else float(distance[~near].max())
    if d_bg - d_fg <= 1e-6:
        weights = blob.astype(np.float32)
    else:
        weights = np.clip((d_bg - distance) / (d_bg - d_fg), 0.0, 1.0) * near
    total = float(weights.sum())
    return (float((weights.sum(axis=0) * np.arange(blob.shape[1])).sum() / total + c0),
            float((weights.sum(axis=1) * np.arange(blob.shape[0])).sum() / total + r0))


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
        detection = detect_marker(view.crop_float(x0, y0, x1, y1), (x0, y0), self.marker,
                                  self.footprint, prediction, touches_region=touches)
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
    rgb = view.crop(*region).astype(np.float32)
    green_blue = 0.5 * (rgb[..., 1] + rgb[..., 2])
    return float((rgb[..., 0] - green_blue).mean() / max(float(green_blue.mean()), 1.0))


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


def track_video(path: str | Path, setup: TrackerSetup, *, threads: bool = True,
                progress: Callable[[str], None] | None = None) -> TrackResult:
    """Track every marker of `setup` and read the LED in every frame of a video (streaming).

    Parameters
    ----------
    path : str or pathlib.Path
        Video file.
    setup : TrackerSetup
    threads : bool
        Let FFmpeg decode with its own threads.
    progress : callable, optional
        Receives a line every 500 frames.

    Returns
    -------
    TrackResult
        Per-frame positions (pixels and metres), validity, LED bits and quality.

    Raises
    ------
    VideoError
        Missing, unreadable or corrupt video.
    """
    footprint = disk_footprint(setup.opening_radius)
    trackers = [MarkerTracker(m, footprint) for m in setup.markers]
    frames, times, levels = [], [], []
    detections: dict[str, list[tuple[float, float, bool]]] = {m.name: [] for m in setup.markers}
    for view in read_frame_views(path, threads=threads):
        frames.append(view.index)
        times.append(view.time)
        for tracker in trackers:
            found = tracker.step(view)
            detections[tracker.marker.name].append((found.x_px, found.y_px, found.valid))
        if setup.led is not None:
            levels.append(read_led_level(view, setup.led.region))
        if progress and (view.index + 1) % 500 == 0:
            progress(f"tracked {view.index + 1} frames")
    tracks = {}
    for marker in setup.markers:
        table = np.array(detections[marker.name], dtype=float).reshape(-1, 3)
        tracks[marker.name] = MarkerTrack.from_pixels(table[:, 0], table[:, 1],
                                                      table[:, 2].astype(bool), marker)
    bits, quality, threshold, overall = classify_led(
        np.array(levels), None if setup.led is None else setup.led.threshold)
    if setup.led is None:
        bits, quality = np.zeros(len(frames), int), np.zeros(len(frames))
    return TrackResult(Path(path), _fps(times), setup, np.array(frames, int), np.array(times),
                       tracks, bits, quality, np.array(levels) if levels else np.full(len(frames),
                                                                                       np.nan),
                       threshold, overall)


def _fps(times: list[float]) -> float:
    if len(times) < 2:
        return 50.0
    return float(round(1.0 / float(np.median(np.diff(times))), 6))


@dataclass(frozen=True)
class MarkerTrack:
    """One marker's per-frame positions: pixels, metres (NaN where lost) and validity."""

    x_px: np.ndarray
    y_px: np.ndarray
    x: np.ndarray
    y: np.ndarray
    valid: np.ndarray

    @classmethod
    def from_pixels(cls, x_px: np.ndarray, y_px: np.ndarray, valid: np.ndarray,
                    marker: MarkerSetup) -> "MarkerTrack":
        x_px = np.where(valid, x_px, np.nan)
        y_px = np.where(valid, y_px, np.nan)
        x, y = marker.to_metres(x_px, y_px)
        return cls(x_px, y_px, x, y, np.asarray(valid, bool))

    @property
    def lost_frames(self) -> int:
        return int(np.count_nonzero(~self.valid))


@dataclass(frozen=True)
class TrackResult:
    """What :func:`track_video` found, frame by frame.

    Attributes
    ----------
    video : pathlib.Path
    fps : float
    setup : TrackerSetup
    frame : numpy.ndarray of int
    time : numpy.ndarray
        Frame times [s] on the camera's clock.
    markers : dict of str to MarkerTrack
    led : numpy.ndarray of int
        LED bit per frame.
    led_quality : numpy.ndarray
        Per-frame confidence of the bit in [0, 1].
    led_level : numpy.ndarray
        Relative red excess of the LED region per frame.
    led_threshold : float
    led_separation : float
        Overall LED quality in [0, 1] (separation of the on/off clusters).
    """

    video: Path
    fps: float
    setup: TrackerSetup
    frame: np.ndarray
    time: np.ndarray
    markers: dict[str, MarkerTrack]
    led: np.ndarray
    led_quality: np.ndarray
    led_level: np.ndarray
    led_threshold: float
    led_separation: float

    @property
    def lost_frames(self) -> dict[str, int]:
        """Frames in which each marker was not found."""
        return {name: track.lost_frames for name, track in self.markers.items()}

    def columns(self) -> dict[str, np.ndarray]:
        """The track file's columns, in order."""
        columns: dict[str, np.ndarray] = {"frame": self.frame, "time": self.time}
        for name, track in self.markers.items():
            columns.update({f"{name}_x_px": track.x_px, f"{name}_y_px": track.y_px,
                            f"{name}_x": track.x, f"{name}_y": track.y,
                            f"{name}_valid": track.valid.astype(int)})
        columns.update({"led": self.led, "led_quality": self.led_quality})
        return columns

    def to_csv(self, path: str | Path) -> Path:
        """Write the track file and its side file ``<path>.json`` (format panto-video-track)."""
        path = Path(path)
        columns = self.columns()
        integer = {"frame", "led"} | {f"{m}_valid" for m in self.markers}
        lines = [",".join(columns)]
        for row in range(self.frame.size):
            lines.append(",".join(str(int(values[row])) if name in integer
                                  else repr(float(values[row]))
                                  for name, values in columns.items()))
        path.write_text("\n".join(lines) + "\n")
        side = {"format": TRACK_FORMAT, "version": 1, "video": str(self.video), "fps": self.fps,
                "markers": list(self.markers), "setup": self.setup.to_dict(),
                "lost_frames": self.lost_frames, "frame_count": int(self.frame.size),
                "led_threshold": self.led_threshold, "led_separation": self.led_separation}
        path.with_name(path.name + ".json").write_text(json.dumps(side, indent=2))
        return path

    @classmethod
    def from_csv(cls, path: str | Path) -> "TrackResult":
        """Read a track file written by :meth:`to_csv` (and its side file)."""
        import pandas as pd

        path = Path(path)
        side_path = path.with_name(path.name + ".json")
        try:
            side = json.loads(side_path.read_text())
            table = pd.read_csv(path)
        except (OSError, json.JSONDecodeError, pd.errors.ParserError) as error:
            raise SetupError(f"{path}: cannot read the track file ({error})") from None
        if side.get("format") != TRACK_FORMAT:
            raise SetupError(f"{side_path}: not a {TRACK_FORMAT!r} side file")
        setup = TrackerSetup.from_dict(side.get("setup", {}), where=f"{side_path}: setup")
        missing = [c for c in cls._expected_columns(side["markers"]) if c not in table]
        if missing:
            raise SetupError(f"{path}: column(s) {missing} missing")
        markers = {}
        for name in side["markers"]:
            markers[name] = MarkerTrack(*(table[f"{name}_{c}"].to_numpy(float)
                                          for c in ("x_px", "y_px", "x", "y")),
                                        table[f"{name}_valid"].to_numpy(int).astype(bool))
        return cls(Path(side["video"]), float(side["fps"]), setup, table["frame"].to_numpy(int),
                   table["time"].to_numpy(float), markers, table["led"].to_numpy(int),
                   table["led_quality"].to_numpy(float), np.full(len(table), np.nan),
                   float(side.get("led_threshold", math.nan)),
                   float(side.get("led_separation", math.nan)))

    @staticmethod
    def _expected_columns(names: list[str]) -> list[str]:
        return ["frame", "time", *(f"{m}_{c}" for m in names
                                   for c in ("x_px", "y_px", "x", "y", "valid")),
                "led", "led_quality"]
