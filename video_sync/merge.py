"""Merging the camera's marker positions into the rig's 500 Hz dataset (thesis section 3.2).

Steps of :func:`sync_and_merge`:

1. read the run (:func:`panto.rig.dataset.read_dataset`) and the track file (:func:`read_track`);
2. align the camera's LED bits with the run's ``led`` channel
   (:func:`panto.video_sync.synchronisation.synchronise`): camera frame ``k`` shows the LED command of
   fine sample ``shift + 10 k``;
3. the image of frame ``k`` belongs to fine sample ``n_k = shift + led_delay + 10 k``: the run loop
   writes the LED *after* reading sample ``n``'s sensors, so the light shows from then until
   sample ``n + 1`` (``led_delay = 1``; the virtual test bed renders it so);
4. crop the run to the fine samples between the first and the last tracked frame;
5. bring each moving marker onto the fine grid (the thesis upsamples): the valid frames are split
   into runs of consecutive frames, and within each run an interpolating cubic spline (not-a-knot;
   linear for 2-3 frames, the sample itself for 1) through the positions at ``n_k`` is evaluated on
   the fine samples; never across a lost frame. Fine samples outside every run are *gap samples*:
   NaN positions and ``video_<marker>_valid = 0``;
6. write ``video_<marker>_x``, ``video_<marker>_y`` [m] and ``video_<marker>_valid`` beside the rig
   channels, and the provenance in ``metadata.extra["video_sync"]``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from panto.rig.dataset import Dataset, read_dataset
from panto.video_sync.plots import plot_synchronisation
from panto.video_sync.synchronisation import SyncError, SyncResult, synchronise

TRACK_FORMAT = "panto-video-track"
#: Markers that do not move with the pantograph (not merged).
STATIC_MARKERS = ("reference",)
_MARKER_FIELDS = ("x_px", "y_px", "x", "y", "valid")


class TrackError(ValueError):
    """A track file violates its format; the message names file, column and row."""


@dataclass(frozen=True)
class Track:
    """A marker track: one row per camera frame.

    Attributes
    ----------
    path : pathlib.Path
    frames : ndarray of int
        Frame numbers (strictly increasing, >= 0).
    time : ndarray
        Camera clock [s] (``frame / fps``).
    fps : float
    markers : tuple of str
    positions : mapping of str to (ndarray, ndarray)
        ``(x, y)`` [m] per marker; NaN where not valid.
    valid : mapping of str to ndarray of bool
    led, led_quality : ndarray
        LED bit (0/1) and its quality (0..1) per frame.
    info : mapping
        The side file's content (video, setup, lost frames).
    """

    path: Path
    frames: np.ndarray
    time: np.ndarray
    fps: float
    markers: tuple[str, ...]
    positions: Mapping[str, tuple[np.ndarray, np.ndarray]]
    valid: Mapping[str, np.ndarray]
    led: np.ndarray
    led_quality: np.ndarray
    info: Mapping[str, Any]

    def led_by_frame(self, min_quality: float = 0.0) -> np.ndarray:
        """LED bits indexed by frame number (NaN: frame missing or quality below the limit)."""
        bits = np.full(int(self.frames[-1]) + 1 if self.frames.size else 0, np.nan)
        keep = self.led_quality >= min_quality
        bits[self.frames[keep]] = self.led[keep]
        return bits


def _read_side(path: Path) -> dict[str, Any]:
    side = path.with_name(path.name + ".json")
    if not side.is_file():
        raise TrackError(f"{path}: side file {side.name} is missing")
    try:
        info = json.loads(side.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise TrackError(f"{side}: not valid JSON ({error})") from None
    if not isinstance(info, dict) or info.get("format") != TRACK_FORMAT:
        raise TrackError(f"{side}: not a {TRACK_FORMAT!r} side file (format = "
                         f"{info.get('format') if isinstance(info, dict) else None!r})")
    if info.get("version") != 1:
        raise TrackError(f"{side}: version {info.get('version')!r} not supported (1 is)")
    fps = info.get("fps")
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise TrackError(f"{side}: fps = {fps!r}: must be a positive number")
    markers = info.get("markers")
    if not (isinstance(markers, list) and markers and all(isinstance(m, str) for m in markers)):
        raise TrackError(f"{side}: markers = {markers!r}: must be a non-empty list of names")
    return info


def _column(frame, name: str, path: Path) -> np.ndarray:
    if name not in frame.columns:
        raise TrackError(f"{path}: column {name!r} is missing; columns are {list(frame.columns)}")
    values = frame[name]
    if values.dtype.kind not in "fiub":
        import pandas as pd

        numbers = pd.to_numeric(values, errors="coerce")
        row = int(np.flatnonzero(numbers.isna() & values.notna())[0])
        raise TrackError(f"{path}: column {name!r}, row {row + 1}: not a number "
                         f"({values.iloc[row]!r})")
    return values.to_numpy(dtype=float)


def _check_bits(values: np.ndarray, name: str, path: Path) -> None:
    bad = ~np.isin(values, (0.0, 1.0))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise TrackError(f"{path}: column {name!r}, row {row + 1}: {float(values[row])!r} "
                         "is not 0/1")


def read_track(path: str | Path) -> Track:
    """Read a track CSV and its ``<name>.csv.json`` side file (format in the module notes of
    :mod:`panto.video_sync.tracking`), checking columns, frame numbers, bits and valid positions.

    Raises
    ------
    TrackError
        Naming the file, the column and the row.
    """
    import pandas as pd

    path = Path(path)
    if not path.is_file():
        raise TrackError(f"{path}: no such track file")
    info = _read_side(path)
    try:
        frame = pd.read_csv(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as error:
        raise TrackError(f"{path}: not a readable CSV ({error})") from None
    frames = _column(frame, "frame", path)
    if frames.size == 0:
        raise TrackError(f"{path}: no frames")
    if not np.all(np.isfinite(frames) & (frames == np.round(frames)) & (frames >= 0)):
        row = int(np.flatnonzero(~(np.isfinite(frames) & (frames == np.round(frames))
                                   & (frames >= 0)))[0])
        raise TrackError(f"{path}: column 'frame', row {row + 1}: {frames[row]!r} is not a "
                         "frame number")
    if np.any(np.diff(frames) <= 0):
        row = int(np.flatnonzero(np.diff(frames) <= 0)[0]) + 1
        raise TrackError(f"{path}: column 'frame' not strictly increasing at row {row + 1}")
    led = _column(frame, "led", path)
    _check_bits(led, "led", path)
    positions, valid = {}, {}
    for marker in info["markers"]:
        columns = {f: _column(frame, f"{marker}_{f}", path) for f in _MARKER_FIELDS}
        _check_bits(columns["valid"], f"{marker}_valid", path)
        ok = columns["valid"] == 1.0
        for axis in ("x", "y"):
            broken = ok & ~np.isfinite(columns[axis])
            if broken.any():
                row = int(np.flatnonzero(broken)[0])
                raise TrackError(f"{path}: column '{marker}_{axis}', row {row + 1}: not finite "
                                 f"although '{marker}_valid' is 1")
        positions[marker] = tuple(np.where(ok, columns[a], np.nan) for a in ("x", "y"))
        valid[marker] = ok
    return Track(path, frames.astype(np.int64), _column(frame, "time", path), float(info["fps"]),
                 tuple(info["markers"]), positions, valid, led,
                 _column(frame, "led_quality", path), info)


def _segments(frames: np.ndarray, ok: np.ndarray) -> list[np.ndarray]:
    """Row indices of the runs of consecutive valid frames."""
    rows = np.flatnonzero(ok)
    if rows.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(frames[rows]) != 1) + 1
    return np.split(rows, breaks)


def upsample_segmentwise(sample_at: np.ndarray, values: np.ndarray, segments: list[np.ndarray],
                         fine: np.ndarray, interpolation: str) -> np.ndarray:
    """Interpolate `values` known at fine positions `sample_at` onto the integer positions
    `fine`, separately inside each segment (NaN outside every segment)."""
    from scipy.interpolate import CubicSpline

    out = np.full(fine.size, np.nan)
    for rows in segments:
        where = (fine >= sample_at[rows[0]]) & (fine <= sample_at[rows[-1]])
        if not where.any():
            continue
        x, y = sample_at[rows].astype(float), values[rows]
        if rows.size == 1:
            out[where] = y[0]
        elif interpolation == "cubic" and rows.size >= 4:
            out[where] = CubicSpline(x, y, bc_type="not-a-knot")(fine[where])
        else:
            out[where] = np.interp(fine[where], x, y)
    return out


def merge_video(dataset: Dataset, track: Track, sync: SyncResult, *,
                interpolation: str = "cubic", led_delay: int = 1) -> Dataset:
    """The run cropped to the tracked interval with the camera positions on its grid.

    Parameters
    ----------
    dataset : Dataset
        The 500 Hz run (uniform grid).
    track : Track
    sync : SyncResult
        From the run's ``led`` and ``track.led_by_frame()``.
    interpolation : {"cubic", "linear"}
    led_delay : int
        Fine samples from the recorded LED command to the frame's image (module notes).

    Returns
    -------
    Dataset
        Channels of the run plus ``video_<m>_x``, ``video_<m>_y`` [m], ``video_<m>_valid`` for
        each moving marker; ``metadata.extra["video_sync"]`` holds the provenance.
    """
    if interpolation not in ("cubic", "linear"):
        raise ValueError(f"interpolation = {interpolation!r}: use 'cubic' or 'linear'")
    sample_at = sync.shift + led_delay + sync.decimation * track.frames
    first, last = max(0, int(sample_at[0])), min(len(dataset) - 1, int(sample_at[-1]))
    if last < first:
        raise SyncError(f"no common interval: the frames cover fine samples {int(sample_at[0])}"
                        f"..{int(sample_at[-1])}, the run has 0..{len(dataset) - 1}")
    fine = np.arange(first, last + 1)
    channels = {n: np.asarray(dataset[n])[first:last + 1] for n in dataset.names}
    units = dict(dataset.units)
    gaps: dict[str, int] = {}
    for marker in (m for m in track.markers if m not in STATIC_MARKERS):
        segments = _segments(track.frames, track.valid[marker])
        for axis, values in zip(("x", "y"), track.positions[marker]):
            channels[f"video_{marker}_{axis}"] = upsample_segmentwise(
                sample_at, values, segments, fine, interpolation)
            units[f"video_{marker}_{axis}"] = "m"
        valid = np.isfinite(channels[f"video_{marker}_y"])
        channels[f"video_{marker}_valid"] = valid.astype(float)
        units[f"video_{marker}_valid"] = "1"
        gaps[marker] = int((~valid).sum())
    rate = float(dataset.metadata.sample_rate)
    merged_frames = int(np.count_nonzero((sample_at >= first) & (sample_at <= last)))
    extra = dict(dataset.metadata.extra)
    extra["video_sync"] = {
        **sync.summary(), "shift_s": sync.shift / rate, "led_delay_samples": led_delay,
        "first_frame_time_s": float(dataset.time[0] + (sync.shift + led_delay) / rate),
        "video": track.info.get("video"), "track_file": str(track.path),
        "interpolation": interpolation, "crop_samples": [first, last],
        "frames_merged": merged_frames, "gap_samples": gaps,
        "lost_frames": track.info.get("lost_frames")}
    metadata = replace(dataset.metadata, extra=extra)
    return Dataset(dataset.time[first:last + 1], channels, units, metadata, dataset.warnings)


@dataclass(frozen=True)
class MergeResult:
    """What :func:`sync_and_merge` did."""

    dataset: Dataset
    sync: SyncResult
    path: Path
    frames_merged: int
    gap_samples: Mapping[str, int]
    plot: Path | None = None


@dataclass(frozen=True, kw_only=True)
class MergeOptions:
    """How :func:`sync_and_merge` synchronises a track with a run and merges the two.

    Parameters
    ----------
    interpolation : {"cubic", "linear"}
        Interpolation of the camera positions onto the run's grid (:func:`merge_video`).
    led_delay : int
        Fine samples from the recorded LED command to the frame's image (module notes).
    min_confidence : float
        Refuse a synchronisation below this normalised correlation.
    min_peak_ratio : float
        Refuse when the best correlation over the second best is below this.
    min_overlap : int
        Frames (with known bits) that must meet fine samples.
    min_led_quality : float
        Camera LED bits of lower quality count as unknown.
    """

    interpolation: str = "cubic"
    led_delay: int = 1
    min_confidence: float = 0.5
    min_peak_ratio: float = 1.5
    min_overlap: int = 250
    min_led_quality: float = 0.0


def sync_and_merge(run_folder: str | Path, track_csv: str | Path, out_folder: str | Path, *,
                   options: MergeOptions | None = None, plot: str | Path | None = None,
                   progress: Callable[[str], None] | None = None) -> MergeResult:
    """Synchronise a track with a run and write the merged dataset ``<out_folder>/run.csv``.

    Nothing is written when the synchronisation is refused (:class:`SyncError`) or an input is
    malformed (:class:`TrackError`, :class:`panto.rig.dataset.DatasetError`).

    Parameters
    ----------
    run_folder : str or pathlib.Path
        A run folder or dataset file.
    track_csv : str or pathlib.Path
    out_folder : str or pathlib.Path
        Created if needed; refused if it already holds ``run.csv``.
    options : MergeOptions, optional
        Interpolation, LED delay and the synchronisation's acceptance thresholds (see
        :func:`merge_video` and :func:`panto.video_sync.synchronisation.synchronise`).
    plot : str or pathlib.Path, optional
        Also draw the correlation (thesis Fig. 3.8) there.
    progress : callable, optional
    """
    options = options or MergeOptions()
    say = progress or (lambda line: None)
    out = Path(out_folder) / "run.csv"
    if out.exists():
        raise FileExistsError(f"{out}: already exists; choose another --out folder")
    dataset = read_dataset(run_folder)
    track = read_track(track_csv)
    say(f"run {run_folder}: {len(dataset)} samples; track {track_csv}: {track.frames.size} "
        "frames")
    if abs(dataset.metadata.sample_rate / track.fps - round(dataset.metadata.sample_rate
                                                            / track.fps)) > 1e-9:
        raise SyncError(f"{dataset.metadata.sample_rate} Hz / {track.fps} fps is not a whole "
                        "number of fine samples per frame")
    decimation = int(round(dataset.metadata.sample_rate / track.fps))
    sync = synchronise(track.led_by_frame(options.min_led_quality), dataset["led"],
                       decimation=decimation, min_confidence=options.min_confidence,
                       min_peak_ratio=options.min_peak_ratio, min_overlap=options.min_overlap)
    say(f"shift {sync.shift} samples (lag {sync.lag}, phase {sync.phase}), confidence "
        f"{sync.confidence:.3f}, peak ratio {sync.peak_ratio:.2f}")
    merged = merge_video(dataset, track, sync, interpolation=options.interpolation,
                         led_delay=options.led_delay)
    info = merged.metadata.extra["video_sync"]
    out.parent.mkdir(parents=True, exist_ok=True)
    merged.write(out)
    picture = Path(plot_synchronisation(sync, str(plot))) if plot else None
    return MergeResult(merged, sync, out, info["frames_merged"], info["gap_samples"], picture)
