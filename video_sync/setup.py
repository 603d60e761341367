"""The tracker's set-up routine (thesis section 3.3.1, Figs. 3.9 and 3.10).

What the thesis' routine asked of the user, done from rough clicks:

- the region in which each marker is expected to stay (Fig. 3.9): a box of `roi_half_size`
  around the click, clipped to the frame;
- the reference colour: the mean RGB of a small disc patch (radius `patch_radius`) around the click,
  inside the marker;
- the threshold: chosen automatically from the histogram of the similarity values
  (:func:`panto.video_sync.tracking.similarity`) in a window around the click, as the two-cluster
  (isodata) threshold between marker and background, i.e. half way between their mean
  similarities; a pixel half covered by the marker lies there, so the thresholded blob has the
  marker's area. It can be overridden per marker;
- the expected radius from the area of the detected blob;
- the scales [mm/px] and offsets [m] the user measured (an object of known length beside each
  marker; the marker's absolute position once), as in the thesis.

For a rendered video, :func:`setup_from_camera` derives all of this from the camera's JSON side
file, so the demo needs no clicks. :func:`panto.video_sync.plots.plot_detection_steps` draws the
detection steps of one frame for a user to check (as thesis Fig. 3.10).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy import ndimage

from panto.video_sync.camera import CameraSetup, load_camera_json
from panto.video_sync.tracking import (LedSetup, MarkerSetup, SetupError, TrackerSetup,
                                 disk_footprint, isodata_threshold, similarity)
from panto.video_sync.video_io import FrameView, VideoError, read_frame_views

#: Marker speed [m/s] the default plausible step allows (one frame at 50 frames/s).
MAX_SPEED = 1.0


def setup_from_camera(camera: CameraSetup | str | Path, *, motion_range: float = 0.13,
                      horizontal_range: float = 0.03) -> TrackerSetup:
    """The tracker set-up of a rendered video, from its camera set-up (no clicks).

    Parameters
    ----------
    camera : CameraSetup or path of the camera side file (``<video>.json``)
    motion_range : float
        Vertical motion [m] each marker may make around its anchor height.
    horizontal_range : float
        Horizontal motion [m] around the anchor.

    Notes
    -----
    Reference colour: the nominal marker colour. Threshold: half way between a perfect match (1)
    and the background's similarity, ``(1 + s_bg) / 2`` (the level of a half-covered pixel).
    Offsets from the anchors: ``x_0 = x_a - 1e-3 s_x c_a``, ``y_0 = y_a + 1e-3 s_y r_a``.
    """
    if not isinstance(camera, CameraSetup):
        camera = load_camera_json(camera)
    markers = []
    for m in camera.markers:
        sx, sy = m.mm_per_px
        margin = 3 * m.radius_px
        reach_x = margin + (horizontal_range / (1e-3 * sx) if m.x_channel else 0)
        reach_y = margin + (motion_range / (1e-3 * sy) if m.y_channel else 0)
        roi = (max(int(m.anchor_px[0] - reach_x), 0), max(int(m.anchor_px[1] - reach_y), 0),
               min(int(m.anchor_px[0] + reach_x) + 1, camera.width),
               min(int(m.anchor_px[1] + reach_y) + 1, camera.height))
        background = float(similarity(np.array(camera.background, float), m.colour))
        markers.append(MarkerSetup(
            m.name, roi, tuple(float(c) for c in m.colour), 0.5 * (1.0 + background), (sx, sy),
            (m.anchor_m[0] - 1e-3 * sx * m.anchor_px[0],
             m.anchor_m[1] + 1e-3 * sy * m.anchor_px[1]),
            float(m.radius_px), MAX_SPEED / camera.fps / (1e-3 * min(sx, sy))))
    led = camera.led
    reach = led.radius_px + 3
    region = (int(led.centre_px[0] - reach), int(led.centre_px[1] - reach),
              int(led.centre_px[0] + reach) + 1, int(led.centre_px[1] + reach) + 1)
    return TrackerSetup(tuple(markers), LedSetup(region))


def read_frame(video: str | Path, index: int = 0) -> FrameView:
    """The frame `index` of a video (decoding up to it)."""
    for view in read_frame_views(video):
        if view.index == index:
            view.rgb()  # decode the whole frame before the decoder moves on
            return view
    raise VideoError(f"{video}: has no frame {index}")


def _patch_colour(rgb: np.ndarray, x: float, y: float, radius: float) -> tuple[float, float, float]:
    rows, columns = np.mgrid[0:rgb.shape[0], 0:rgb.shape[1]]
    patch = (columns - x) ** 2 + (rows - y) ** 2 <= radius ** 2
    if not patch.any():
        raise SetupError(f"click ({x}, {y}) lies outside the frame")
    return tuple(float(v) for v in rgb[patch].mean(axis=0))


@dataclass(frozen=True, kw_only=True)
class MarkerOptions:
    """How :func:`setup_marker` turns a rough click into a marker's set-up (module notes).

    Parameters
    ----------
    roi_half_size : (int, int)
        Half width and half height [px] of the region the marker is expected to stay in.
    patch_radius : float
        Radius [px] of the disc around the click whose mean colour is the reference colour.
    window : int
        Half size [px] of the square around the click whose similarity values set the threshold.
    max_step_px : float
        Farthest [px] a detection may lie from the tracker's prediction before it counts as lost.
    """

    roi_half_size: tuple[int, int] = (80, 300)
    patch_radius: float = 3.0
    window: int = 30
    max_step_px: float = 40.0


def setup_marker(rgb: np.ndarray, name: str, click: tuple[float, float], *,
                 mm_per_px: tuple[float, float], offset: tuple[float, float] = (0.0, 0.0),
                 threshold: float | None = None,
                 options: MarkerOptions | None = None) -> MarkerSetup:
    """Set up one marker from a rough click (x, y) [px] in the RGB frame `rgb`.

    `threshold` overrides the automatic one; `options` default to ``MarkerOptions()``.
    """
    options = options or MarkerOptions()
    roi_half_size, window = options.roi_half_size, options.window
    height, width = rgb.shape[:2]
    x, y = click
    if not (0 <= x < width and 0 <= y < height):
        raise SetupError(f"marker {name!r}: click ({x}, {y}) outside the {width}x{height} frame")
    colour = _patch_colour(rgb, x, y, options.patch_radius)
    x0, y0 = max(int(x) - window, 0), max(int(y) - window, 0)
    near = similarity(rgb[y0:int(y) + window + 1, x0:int(x) + window + 1], colour)
    if threshold is None:
        threshold = isodata_threshold(near.ravel())
    opened = ndimage.binary_opening(near > threshold, structure=disk_footprint(2))
    labels, _ = ndimage.label(opened, structure=np.ones((3, 3), bool))
    clicked = labels[int(round(y)) - y0, int(round(x)) - x0]
    if clicked == 0:
        raise SetupError(f"marker {name!r}: no blob of the marker's colour at the click "
                         f"({x}, {y}) with threshold {threshold:.3f}")
    radius = math.sqrt(np.count_nonzero(labels == clicked) / math.pi)
    roi = (max(int(x - roi_half_size[0]), 0), max(int(y - roi_half_size[1]), 0),
           min(int(x + roi_half_size[0]) + 1, width), min(int(y + roi_half_size[1]) + 1, height))
    return MarkerSetup(name, roi, colour, float(threshold), tuple(map(float, mm_per_px)),
                       tuple(map(float, offset)), radius, float(options.max_step_px))


def make_setup(video: str | Path, clicks: Mapping[str, tuple[float, float]], *,
               led: tuple[float, float] | None, mm_per_px: Mapping[str, tuple[float, float]] |
               tuple[float, float], offsets: Mapping[str, tuple[float, float]] | None = None,
               thresholds: Mapping[str, float] | None = None, frame_index: int = 0,
               led_half_size: int = 8, **options: Any) -> TrackerSetup:
    """The set-up routine: markers from rough clicks on one frame, the LED region, the scales.

    Parameters
    ----------
    video : str or pathlib.Path
    clicks : mapping of str to (x, y)
        Rough pixel position of each marker in frame `frame_index`.
    led : (x, y) or None
        Rough pixel position of the LED.
    mm_per_px : (s_x, s_y) for all markers, or a mapping marker -> (s_x, s_y)
    offsets : mapping marker -> (x_0, y_0) [m], optional
        Absolute position of pixel (0, 0) in each marker's plane (default (0, 0): relative).
    thresholds : mapping marker -> float, optional
        Overrides of the automatic threshold.
    frame_index : int
    led_half_size : int
        Half size [px] of the LED's square region.
    **options
        Fields of :class:`MarkerOptions` for every marker (e.g. ``roi_half_size``).
    """
    rgb = read_frame(video, frame_index).rgb()
    markers = []
    for name, click in clicks.items():
        scale = mm_per_px[name] if isinstance(mm_per_px, Mapping) else mm_per_px
        markers.append(setup_marker(rgb, name, click, mm_per_px=scale,
                                    offset=(offsets or {}).get(name, (0.0, 0.0)),
                                    threshold=(thresholds or {}).get(name),
                                    options=MarkerOptions(**options)))
    region = None
    if led is not None:
        region = LedSetup((max(int(led[0]) - led_half_size, 0), max(int(led[1]) - led_half_size, 0),
                           int(led[0]) + led_half_size + 1, int(led[1]) + led_half_size + 1))
    return TrackerSetup(tuple(markers), region)
