"""Benchmark: video tracking throughput (decode + track four markers and the LED, 1080p H.264).

Run by hand; writes benchmarks/video_tracking_speed.json and benchmarks/video_tracking_speed.md.

    .venv/bin/python benchmarks/video_tracking_speed.py [--duration 6] [--presets superfast,...]

A clip of the synthetic camera (1920 x 1080, 50 frames/s, H.264 4:4:4, crf 18, a keyframe every
second) is rendered from known marker paths, then read back in several ways; frames per second
(the fastest of ``--repeat`` runs) are given against the wall clock and against CPU time (this
process plus its worker processes; the machine is shared: CPU time is what the work costs, wall
time what it took among the other processes):

``decode``: decoding alone (no pixel conversion), with FFmpeg's decoder threads off and with
its three thread types; ``decode + full RGB``: every frame converted to RGB (what a tracker
working on whole frames pays first); ``track``: :func:`track_video`, which converts only the
regions it looks at (four marker windows and the LED region), serially in this process
(``workers=1``) and on keyframe-aligned segments in two worker processes (``workers=2``).
Goal: tracking at least 4 x the camera's 50 frames/s. The x264 preset of the encoding changes
the decoding cost (``ultrafast`` has no CABAC and no deblocking filter), so clips of several
presets are compared.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from panto.rig.dataset import Dataset, RunMetadata  # noqa: E402
from panto.video_sync.camera import CameraSetup, render_run  # noqa: E402
from panto.video_sync.setup import setup_from_camera  # noqa: E402
from panto.video_sync.tracking import track_video  # noqa: E402
from panto.video_sync.video_io import _decoded, read_frame_views  # noqa: E402

HERE = Path(__file__).resolve().parent


def _truth(seconds: float) -> Dataset:
    rng = np.random.default_rng(0)
    time_ = np.arange(0.0, seconds, 0.002)
    channels = {"x_cb": 0.105 + 0.004 * np.sin(2 * np.pi * 0.7 * time_),
                "xi": 2.0 + 0.10 * np.sin(2 * np.pi * 1.3 * time_ + 1.0),
                "y_cb": 2.01 + 0.08 * np.sin(2 * np.pi * 1.1 * time_),
                "eta": 2.0 + 0.05 * np.sin(2 * np.pi * 2.0 * time_ + 2.0)}
    led, bit = [], 0
    while len(led) < time_.size:
        led += [bit] * int(rng.integers(3, 16))
        bit = 1 - bit
    channels["led"] = np.array(led[:time_.size], dtype=float)
    return Dataset(time_, channels, {n: "m" for n in channels} | {"led": "1"},
                   RunMetadata(sample_rate=500.0, source="emulator"))


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished children (the worker processes)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def _machine_busy_seconds() -> float:
    """CPU time all processes of the machine have used since boot (from /proc/stat)."""
    fields_ = [int(v) for v in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    user, nice, system, _, _, irq, softirq, steal = fields_[:8]
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def _measure(work) -> dict:
    load = os.getloadavg()[0]
    busy = _machine_busy_seconds()
    wall, cpu = time.perf_counter(), _cpu_seconds()
    frames = work()
    wall, cpu = time.perf_counter() - wall, _cpu_seconds() - cpu
    others = max(_machine_busy_seconds() - busy - cpu, 0.0) / wall
    return {"frames": frames, "wall_s": wall, "cpu_s": cpu, "fps_wall": frames / wall,
            "fps_cpu": frames / cpu, "load_before": load, "other_work_cores": others}


DECODER_THREADS = {"off": False, "SLICE": "SLICE", "FRAME": "FRAME", "AUTO": "AUTO"}


def _best(work, repeat: int) -> dict:
    """The run with the highest wall-clock rate of `repeat` (the least disturbed by other work)."""
    runs = [_measure(work) for _ in range(repeat)]
    best = max(runs, key=lambda run: run["fps_wall"])
    return best | {"runs": len(runs), "fps_wall_all": [run["fps_wall"] for run in runs]}


def _cases(path: Path, setup, repeat: int) -> dict:
    def decode(threads):
        return lambda: sum(1 for _ in _decoded(path, threads=threads))

    def full_rgb():
        return sum(1 for view in read_frame_views(path) if view.rgb() is not None)

    def track(workers, threads=False):
        def run():
            result = track_video(path, setup, workers=workers, threads=threads)
            assert all(v == 0 for v in result.lost_frames.values()), result.lost_frames
            return int(result.frame.size)
        return run

    cases = {f"decode, threads {name}": _best(decode(value), repeat)
             for name, value in DECODER_THREADS.items()}
    cases["decode + full RGB"] = _best(full_rgb, repeat)
    cases["track, serial"] = _best(track(1), repeat)
    cases["track, serial, FRAME threads"] = _best(track(1, "FRAME"), repeat)
    cases["track, 2 processes"] = _best(track(2), repeat)
    return cases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=6.0, help="clip length [s]")
    parser.add_argument("--presets", default="superfast,ultrafast",
                        help="x264 presets of the clips (comma separated)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs per case; the fastest (least disturbed) is kept")
    args = parser.parse_args()
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, "
                          f"Python {platform.python_version()}",
               "clip": f"1920x1080, 50 fps, H.264 yuv444p crf 18, keyframe every 1 s, "
                       f"{args.duration:g} s, no shadow", "presets": {}}
    camera = CameraSetup(shadow=None)
    with tempfile.TemporaryDirectory() as folder:
        for preset in args.presets.split(","):
            path = Path(folder) / f"clip-{preset}.mp4"
            render_run(_truth(args.duration + 1), path, setup=camera, rng=1,
                       duration=args.duration, start_sample=0, preset=preset)
            setup = setup_from_camera(camera)
            entry = {"size_MB": path.stat().st_size / 1e6, "load_before": os.getloadavg()[0],
                     "cases": _cases(path, setup, args.repeat), "load_after": os.getloadavg()[0]}
            results["presets"][preset] = entry
            print(preset, json.dumps(entry, indent=1), flush=True)
    (HERE / "video_tracking_speed.json").write_text(json.dumps(results, indent=2))
    _write_markdown(results)


def _write_markdown(results: dict) -> None:
    presets = results["presets"]
    names = list(next(iter(presets.values()))["cases"])
    lines = ["# Video tracking throughput (decode + track, 1080p H.264)", "",
             f"Date: {results['date']}. Machine: {results['machine']}, shared with other work "
             "(the 1-minute load average before each case is in the JSON; before/after each "
             "clip below). Clip: " + results["clip"] + ".", "",
             "Frames per second against the wall clock and against CPU time (this process and "
             "its worker processes), the fastest of several runs; in brackets the cores other "
             "work kept busy during that run (from /proc/stat). Goal: tracking >= 200 "
             "frames/s (4 x the camera's 50).", "",
             "| case | " + " | ".join(presets) + " |", "|---|" + "---|" * len(presets)]
    for name in names:
        cells = [f"{e['cases'][name]['fps_wall']:.0f} wall / {e['cases'][name]['fps_cpu']:.0f} CPU"
                 f" ({e['cases'][name]['other_work_cores']:.1f})" for e in presets.values()]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("| load average before / after | " + " | ".join(
        f"{e['load_before']:.1f} / {e['load_after']:.1f}" for e in presets.values()) + " |")
    lines += ["", "## Reading", ""]
    for preset, entry in presets.items():
        cases = entry["cases"]
        decode = 1e3 / cases["decode, threads off"]["fps_cpu"]
        track = 1e3 / cases["track, serial"]["fps_cpu"]
        full = 1e3 / cases["decode + full RGB"]["fps_cpu"] - decode
        parallel = cases["track, 2 processes"]
        met = "meets" if parallel["fps_wall"] >= 200 else "misses"
        lines.append(f"- {preset}: decoding {decode:.1f} ms of CPU per frame, tracking four "
                     f"markers and the LED {track - decode:.1f} ms on top (converting the whole "
                     f"frame to RGB alone would cost {full:.1f} ms). Two processes: "
                     f"{parallel['fps_wall']:.0f} frames/s wall, {parallel['fps_cpu']:.0f} per "
                     f"CPU-second, so at most {2 * parallel['fps_cpu']:.0f} frames/s with both "
                     f"cores free; {met} the 200 frames/s goal on this run.")
    lines += ["- What sets the limit: with a CABAC stream (superfast, the synthetic camera's "
              "default) FFmpeg's H.264 decoder, about 14 ms of CPU per frame of this "
              "sensor-noisy 4:4:4 "
              "stream (~30 Mbit/s), so even two free cores stay near 2 x 64 frames/s; tracking "
              "(marker windows converted from YUV element by element, opening and labelling on "
              "the blob's bounding box) costs under 2 ms. FFmpeg's decoder threads give no gain "
              "per CPU-second (frame threads cost ~10 % more CPU on ultrafast) and cannot decode "
              "only some planes, so the parallelism is across processes, on segments cut at "
              "keyframes (a keyframe every second). Two processes need a free second core: with "
              "one core kept busy by other work (the bracketed figures) they share one core "
              "and lose ~10 % to switching; the 'with both cores free' figures are 2 x the CPU "
              "rate."]
    (HERE / "video_tracking_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
