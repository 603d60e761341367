"""Benchmark: the demo's camera step for one run, before and after session 34, in the same run.

Run by hand on a run folder of a ``panto demo`` output; writes benchmarks/demo_filming_speed.json
and benchmarks/demo_filming_speed.md.

    .venv/bin/python -P benchmarks/demo_filming_speed.py OUT/runs/training_0001 [--repeat 2]

Each case calls :func:`panto.demo_steps._film_one` as ``panto demo`` does (camera at half
resolution, a 30 s window: 1501 frames of 960 x 540; render, H.264 encode, track, synchronise,
merge) on a copy of the run folder:

``before``: the camera's default encoding (libx264 ``superfast``, crf 18) and the lighting table
applied by fancy indexing, as the demo filmed until session 33;
``after``: the demo's encoding (:data:`panto.demo_steps.VIDEO_PRESET`, ``VIDEO_CRF``) and the
renderer as it is (:meth:`panto.video_sync.camera.CameraRenderer.lit_screen`).

A short untimed call first loads the modules (a step's first call in a fresh process imports
SciPy's signal package and Matplotlib). The cases alternate (before, after, after, before, ...)
so a change in the other work on the machine falls on both; per phase the wall time and the CPU
time of this process (libx264's threads included) are summed, and the ratio before / after of
the medians is reported. The demo runs this step beside the identification and the diagnosis on
two cores, so its CPU time is what it takes from them. The demo's outcome (synchronisation,
lost frames, video against laser) is listed for both, to show it does not change.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import panto.demo_steps as demo_steps  # noqa: E402
import panto.video_sync.camera as camera  # noqa: E402
import panto.video_sync.merge as merge  # noqa: E402
import panto.video_sync.tracking as tracking  # noqa: E402
from panto.video_sync.video_io import VideoWriter  # noqa: E402

HERE = Path(__file__).resolve().parent
PHASES = ("render + encode", "encode", "decode + track", "sync + merge", "total")


class IndexedTable(camera.CameraRenderer):
    """The renderer before session 34: the lighting table applied by fancy indexing."""

    def lit_screen(self, frame: int, gain: float) -> np.ndarray:
        lut = np.clip(np.arange(256) * gain + 0.5, 0, 255).astype(np.uint8)
        return lut[self._bank[frame % self._BANK]]


class PhaseClock:
    """Sums the wall and CPU seconds spent inside patched functions, per phase."""

    def __init__(self) -> None:
        self.wall = dict.fromkeys(PHASES, 0.0)
        self.cpu = dict.fromkeys(PHASES, 0.0)

    def wrap(self, phase: str, function):
        def timed(*args, **kwargs):
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                self.wall[phase] += time.perf_counter() - wall
                self.cpu[phase] += time.process_time() - cpu
        return timed


@contextmanager
def _patched(targets: list[tuple[object, str, object]]):
    """Set attributes for the duration of one case and restore them."""
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in targets]
    for owner, name, value in targets:
        setattr(owner, name, value)
    try:
        yield
    finally:
        for owner, name, value in saved:
            setattr(owner, name, value)


def _film(case: str, run: Path, work: Path, window: float) -> dict:
    """One call of the demo's ``_film_one`` on a fresh copy of `run`, timed per phase."""
    folder = work / f"{case}_run"
    shutil.rmtree(folder, ignore_errors=True)
    shutil.copytree(run, folder, ignore=shutil.ignore_patterns("video_merged"))
    clock = PhaseClock()
    targets = [(camera, "render_run", clock.wrap("render + encode", camera.render_run)),
               (VideoWriter, "write", clock.wrap("encode", VideoWriter.write)),
               (VideoWriter, "close", clock.wrap("encode", VideoWriter.close)),
               (tracking, "track_video", clock.wrap("decode + track", tracking.track_video)),
               (merge, "sync_and_merge", clock.wrap("sync + merge", merge.sync_and_merge))]
    if case == "before":
        targets += [(camera, "CameraRenderer", IndexedTable),
                    (demo_steps, "VIDEO_PRESET", "superfast"), (demo_steps, "VIDEO_CRF", 18.0)]
    settings = SimpleNamespace(video_scale=0.5, video_window=window, workers=1)
    with _patched(targets):
        summary = clock.wrap("total", demo_steps._film_one)(
            "training", folder, work / f"{case}_video", settings, lambda line: None)
    video = work / f"{case}_video" / summary["video"]
    return {"wall_s": clock.wall, "cpu_s": clock.cpu, "video_MB": video.stat().st_size / 1e6,
            "load_before": os.getloadavg()[0],
            "outcome": {key: summary[key] for key in (
                "frames", "sync_confidence", "shift_samples", "sync_error_samples",
                "lost_frames", "video_vs_laser")}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a run folder of a panto demo output")
    parser.add_argument("--window", type=float, default=30.0, help="video window [s]")
    parser.add_argument("--repeat", type=int, default=2, help="runs per case")
    args = parser.parse_args()
    if not (args.run / "truth.csv").is_file() or not (args.run / "run.csv").is_file():
        sys.exit(f"{args.run}: not a run folder of a panto demo output (needs truth.csv and "
                 f"run.csv, e.g. OUT/runs/training_0001)")
    if args.repeat < 1 or args.window <= 0:
        sys.exit(f"--repeat {args.repeat} must be >= 1 and --window {args.window} > 0")
    order = [("before", "after") if k % 2 == 0 else ("after", "before")
             for k in range(args.repeat)]
    runs: dict[str, list[dict]] = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as work:
        _film("warm-up", args.run, Path(work), 6.0)  # imports and caches land here, untimed
        for pair in order:
            for case in pair:
                runs[case].append(_film(case, args.run, Path(work), args.window))
                print(case, json.dumps(runs[case][-1]["cpu_s"]), flush=True)
    median = {case: {kind: {p: float(np.median([r[kind][p] for r in done])) for p in PHASES}
                     for kind in ("wall_s", "cpu_s")} for case, done in runs.items()}
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, "
                          f"Python {platform.python_version()}",
               "run": str(args.run), "window_s": args.window, "order": order,
               "encoding": {"before": "libx264 superfast crf 18",
                            "after": f"libx264 {demo_steps.VIDEO_PRESET} crf "
                                     f"{demo_steps.VIDEO_CRF:g}"},
               "median": median,
               "ratio_before_over_after": {kind: {p: median["before"][kind][p]
                                                  / max(median["after"][kind][p], 1e-9)
                                                  for p in PHASES}
                                           for kind in ("wall_s", "cpu_s")},
               "runs": runs}
    (HERE / "demo_filming_speed.json").write_text(json.dumps(results, indent=2))
    _write_markdown(results)


def _write_markdown(results: dict) -> None:
    median, ratio = results["median"], results["ratio_before_over_after"]
    first = {case: done[0] for case, done in results["runs"].items()}
    lines = ["# The demo's camera step, one run: before and after session 34", "",
             f"Date: {results['date']}. Machine: {results['machine']}, shared with other work. "
             f"Run folder: `{results['run']}`, window {results['window_s']:g} s at half "
             f"resolution (960 x 540), as `panto demo` films it. Cases in the order "
             f"{results['order']}; medians of {len(results['runs']['before'])} runs each.", "",
             f"Before: {results['encoding']['before']}, lighting table by fancy indexing. "
             f"After: {results['encoding']['after']}, lighting table by `take` (the same "
             f"rendered pixels, `tests/test_video_demo_encoding.py`).", "",
             "| phase | CPU before [s] | CPU after [s] | CPU ratio | wall before [s] | "
             "wall after [s] | wall ratio |", "|---|---|---|---|---|---|---|"]
    for phase in PHASES:
        lines.append(f"| {phase} | {median['before']['cpu_s'][phase]:.1f} | "
                     f"{median['after']['cpu_s'][phase]:.1f} | "
                     f"{ratio['cpu_s'][phase]:.2f} | {median['before']['wall_s'][phase]:.1f} | "
                     f"{median['after']['wall_s'][phase]:.1f} | {ratio['wall_s'][phase]:.2f} |")
    lines += ["", "'render + encode' holds 'encode' (libx264, with its RGB -> YUV conversion); "
              "'total' also holds the tracker set-up, reading the run, the sync plot.", "",
              "## The demo's outcome (first run of each case)", "",
              "| | before | after |", "|---|---|---|"]
    for key in ("frames", "sync_confidence", "shift_samples", "sync_error_samples",
                "lost_frames"):
        lines.append(f"| {key} | {first['before']['outcome'][key]} | "
                     f"{first['after']['outcome'][key]} |")
    for key in ("rms_mm", "mean_mm", "std_mm"):
        lines.append(f"| video vs laser {key} | "
                     f"{first['before']['outcome']['video_vs_laser'][key]:.3f} | "
                     f"{first['after']['outcome']['video_vs_laser'][key]:.3f} |")
    lines.append(f"| video file [MB] | {first['before']['video_MB']:.1f} | "
                 f"{first['after']['video_MB']:.1f} |")
    (HERE / "demo_filming_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
