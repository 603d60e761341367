"""The tracker's files: its set-up (JSON) and its result, the track file (CSV + JSON side file).

A set-up file (format ``panto-video-setup``, version 1) holds :class:`TrackerSetup`: per marker
its region, reference colour, similarity threshold, scale and offset, disc radius and largest
step, then the LED's region and the opening's disk radius.

A track file holds one row per video frame and the columns ``frame, time``, then per marker
``<name>_x_px, <name>_y_px, <name>_x, <name>_y, <name>_valid`` (pixels, metres, 0/1), then
``led, led_quality``. Its side file ``<track>.json`` (format ``panto-video-track``, version 1)
holds the video, the frame rate, the marker names, the tracker set-up, the lost-frame counts and
the LED threshold and separation. :func:`panto.video_sync.tracking.track_video` makes a
:class:`TrackResult`; :meth:`TrackResult.to_csv` and :meth:`TrackResult.from_csv` write and read
the pair. Every name here is also importable from :mod:`panto.video_sync.tracking`.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import numpy as np

TRACK_FORMAT = "panto-video-track"
SETUP_FORMAT = "panto-video-setup"
_COLUMNS = ("x_px", "y_px", "x", "y")


class SetupError(ValueError):
    """A tracker set-up (file) is incomplete or wrong; names the file and the field."""


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
        """Positions in pixels -> metres with the marker's scale and offset (NaN where lost)."""
        x_px = np.where(valid, x_px, np.nan)
        y_px = np.where(valid, y_px, np.nan)
        x, y = marker.to_metres(x_px, y_px)
        return cls(x_px, y_px, x, y, np.asarray(valid, bool))

    @property
    def lost_frames(self) -> int:
        """Frames in which the marker was not found."""
        return int(np.count_nonzero(~self.valid))


@dataclass(frozen=True)
class TrackResult:
    """What :func:`panto.video_sync.tracking.track_video` found, frame by frame.

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
        """Read a track file written by :meth:`to_csv` (and its side file).

        Raises
        ------
        SetupError
            Unreadable file, wrong side-file format or missing columns (names the file).
        """
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
        missing = [c for c in expected_columns(side["markers"]) if c not in table]
        if missing:
            raise SetupError(f"{path}: column(s) {missing} missing")
        markers = {name: MarkerTrack(*(table[f"{name}_{c}"].to_numpy(float) for c in _COLUMNS),
                                     table[f"{name}_valid"].to_numpy(int).astype(bool))
                   for name in side["markers"]}
        return cls(Path(side["video"]), float(side["fps"]), setup, table["frame"].to_numpy(int),
                   table["time"].to_numpy(float), markers, table["led"].to_numpy(int),
                   table["led_quality"].to_numpy(float), np.full(len(table), np.nan),
                   float(side.get("led_threshold", math.nan)),
                   float(side.get("led_separation", math.nan)))


def expected_columns(names: list[str]) -> list[str]:
    """The columns of a track file with the markers `names`, in order."""
    return ["frame", "time", *(f"{m}_{c}" for m in names for c in (*_COLUMNS, "valid")),
            "led", "led_quality"]
