"""``panto video``: the synthetic camera, the tracker's set-up and marker tracking.

``panto video render RUN_FOLDER --out VIDEO`` films a virtual run with the synthetic camera;
``panto video setup VIDEO --camera CAMERA_JSON --out setup.json`` (or from rough clicks:
``--marker NAME=X,Y ... --led X,Y --scale MM_PER_PX``) writes the tracker set-up;
``panto video track VIDEO --setup setup.json --out track.csv`` tracks the markers and reads the LED.
"""
from __future__ import annotations

import argparse
from typing import Callable

from panto.console import progress, say, write_json
from panto.data_options import non_negative_int, positive_float


def _pair(text: str, what: str) -> tuple[float, float]:
    try:
        first, second = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"{what} {text!r}: expected two numbers 'X,Y'") from None
    return first, second


def _named(items: list[str] | None, what: str) -> dict[str, str]:
    named = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"{what} {item!r}: expected NAME=VALUE")
        named[name] = value
    return named


def run_video_render(args: argparse.Namespace) -> int:
    """Film a virtual run (its truth.csv) with the synthetic camera."""
    from panto.video_sync.camera import CameraSetup, render_run

    setup = CameraSetup() if args.scale == 1.0 else CameraSetup().reduced(args.scale)
    result = render_run(args.run_folder, args.out, setup=setup, codec=args.codec, rng=args.seed,
                        duration=args.duration, progress=progress)
    say(f"wrote {result.path} ({result.frame_count} frames at {result.fps:g} fps, {args.codec}) "
        f"and {result.camera_json}")
    return 0


def _scales(args: argparse.Namespace, names: list[str]):
    scales = {}
    for item in args.scale or []:
        name, sep, value = item.rpartition("=")
        numbers = [float(v) for v in value.split(",")]
        scale = (numbers[0], numbers[-1])
        for target in ([name] if sep else names):
            scales[target] = scale
    missing = [n for n in names if n not in scales]
    if missing:
        raise ValueError(f"--scale: no mm/px scale for marker(s) {missing}")
    return scales


def run_video_setup(args: argparse.Namespace) -> int:
    """Write a tracker set-up from the camera's side file or from rough clicks."""
    from panto.video_sync.plots import plot_detection_steps
    from panto.video_sync.setup import make_setup, read_frame, setup_from_camera

    if args.camera:
        read_frame(args.video, args.frame)  # the set-up is for a video that opens
        setup = setup_from_camera(args.camera)
    else:
        clicks = {n: _pair(v, f"--marker {n}") for n, v in _named(args.marker, "--marker").items()}
        if not clicks:
            raise ValueError("give --camera CAMERA_JSON or at least one --marker NAME=X,Y")
        offsets = {n: _pair(v, f"--offset {n}") for n, v in _named(args.offset, "--offset").items()}
        thresholds = {n: float(v) for n, v in _named(args.threshold, "--threshold").items()}
        setup = make_setup(args.video, clicks, led=_pair(args.led, "--led") if args.led else None,
                           mm_per_px=_scales(args, list(clicks)), offsets=offsets,
                           thresholds=thresholds, frame_index=args.frame)
    setup.save(args.out)
    for marker in setup.markers:
        say(f"{marker.name:>10}: region {list(marker.roi)}, colour "
            f"{[round(c) for c in marker.colour]}, threshold {marker.threshold:.3f}, "
            f"radius {marker.radius_px:.1f} px")
    say(f"wrote {args.out}")
    if args.picture:
        say(f"wrote {plot_detection_steps(args.video, setup, args.frame, args.picture)}")
    return 0


def run_video_track(args: argparse.Namespace) -> int:
    """Track the markers and read the LED; write the track file."""
    from panto.video_sync.tracking import TrackerSetup, track_video

    result = track_video(args.video, TrackerSetup.load(args.setup), progress=progress)
    result.to_csv(args.out)
    say(f"{result.frame.size} frames; LED quality {result.led_separation:.3f} "
        f"(threshold {result.led_threshold:.3f})")
    for name, lost in result.lost_frames.items():
        say(f"  {name:>10}: {lost} lost frames")
    say(f"wrote {args.out}")
    if args.json:
        write_json(args.json, {
            "video": str(args.video), "frames": int(result.frame.size),
            "lost_frames": result.lost_frames, "led_quality": result.led_separation,
            "led_threshold": result.led_threshold})
    return 0


def register(add: Callable) -> None:
    """Declare ``panto video`` with its sub-subcommands."""
    video = add("video", _dispatch, "video sidecar: synthetic camera, tracker set-up, tracking")
    sub = video.add_subparsers(dest="video_command", required=True,
                               help="what to do; 'panto video WHAT --help' for its options")

    p = sub.add_parser("render", help="film a virtual run with the synthetic camera")
    p.set_defaults(video_handler=run_video_render)
    p.add_argument("run_folder", help="virtual run folder (with truth.csv) or a truth CSV")
    p.add_argument("--out", required=True, help="video file (.mp4 or .mkv)")
    p.add_argument("--codec", default="h264", choices=("h264", "h264-420", "lossless"),
                   help="video codec (default h264)")
    p.add_argument("--duration", type=positive_float, help="film at most this long [s]")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of start instant, noise, lighting")
    p.add_argument("--scale", type=positive_float, default=1.0,
                   help="resolution factor (1: 1920x1080; smaller for quick looks)")

    p = sub.add_parser("setup", help="write a tracker set-up (from the camera file or clicks)")
    p.set_defaults(video_handler=run_video_setup)
    p.add_argument("video", help="video file the set-up is for (.mp4 or .mkv)")
    p.add_argument("--camera", help="camera side file of a rendered video (<video>.json)")
    p.add_argument("--marker", action="append", help="NAME=X,Y rough pixel position (repeat)")
    p.add_argument("--led", help="X,Y rough pixel position of the LED")
    p.add_argument("--scale", action="append",
                   help="MM_PER_PX[,MM_PER_PX_Y] for all markers, or NAME=SX[,SY] (repeat)")
    p.add_argument("--offset", action="append",
                   help="NAME=X,Y absolute position [m] of pixel (0, 0) in the marker's plane")
    p.add_argument("--threshold", action="append", help="NAME=T overrides the automatic one")
    p.add_argument("--frame", type=non_negative_int, default=0, help="frame used for the set-up")
    p.add_argument("--out", required=True, help="set-up file (JSON)")
    p.add_argument("--picture", help="PNG of the detection steps (thesis Fig. 3.10)")

    p = sub.add_parser("track", help="track the markers and read the LED in a video")
    p.set_defaults(video_handler=run_video_track)
    p.add_argument("video", help="video file to track (.mp4 or .mkv)")
    p.add_argument("--setup", required=True, help="tracker set-up file (JSON)")
    p.add_argument("--out", required=True, help="track file (CSV; side file <out>.json)")
    p.add_argument("--json", help="also write a summary as JSON")


def _dispatch(args: argparse.Namespace) -> int:
    return args.video_handler(args)
