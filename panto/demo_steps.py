"""Steps 1-2 of the main job: the FMUs, the rig campaign and the camera video (:mod:`panto.demo`).

Each step is ``step(state, progress) -> dict``: it reads what earlier steps left in `state`
(``out``, ``settings``, ``fmus``, ``runs``, ...), adds its own results there, and returns the
JSON-ready part of ``summary.json``.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

Progress = Callable[[str], None]

#: The thesis' rig campaign: label, embedded profile, seed of the sensor noise.
CAMPAIGN = (("training", "aprbs_training.json", 1), ("validation", "ramps_validation.json", 2))

#: The demo camera's libx264 encoding: "ultrafast" (no CABAC, B-frames or deblocking) at crf 16
#: encodes a run in about half the CPU time of the camera's default ("superfast", crf 18), and
#: the tracker decodes it in about half; the tracked centres are as close to the camera's truth
#: (``benchmarks/demo_filming_speed.md``, ``tests/test_video_demo_encoding.py``).
VIDEO_PRESET, VIDEO_CRF = "ultrafast", 16.0


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Fit % = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) over the finite samples (thesis 4.1.3)."""
    ok = np.isfinite(measured) & np.isfinite(simulated)
    y, y_hat = measured[ok], simulated[ok]
    return float(100 * (1 - np.linalg.norm(y - y_hat) / np.linalg.norm(y - y.mean())))


def build_fmus(state: dict[str, Any], progress: Progress) -> dict:
    """Step 1: generate, compile, package and validate the FMUs into ``out/fmus``.

    Each FMU is compiled on its own (one C compiler process at a time), so the list is cut in
    ``settings.workers`` consecutive parts built side by side (:func:`_side_by_side`): the same
    files, and the progress lines in the same order.
    """
    from panto.fmu_src.models import FMU_NAMES

    out, settings = state["out"], state["settings"]
    names = tuple(settings.fmu_names or FMU_NAMES)
    size = -(-len(names) // max(1, settings.workers))
    jobs = [(out / "fmus", names[i:i + size], settings.fmi_versions)
            for i in range(0, len(names), size)]
    built = [b for part in _side_by_side(_build_part, jobs, settings.workers, progress)
             for b in part]
    fmus = [{"file": b.path.name, "fmi_version": b.fmi_version, "valid": not b.problems,
             "problems": list(b.problems)} for b in built]
    invalid = [f["file"] for f in fmus if not f["valid"]]
    if invalid:
        raise RuntimeError(f"fmpy's validator rejected {invalid}")
    state["fmus"] = out / "fmus"
    return {"fmus": fmus, "all_valid": True, "count": len(fmus)}


def _build_part(folder: Path, names: tuple[str, ...], fmi_versions: tuple[int, ...],
                progress: Progress) -> list:
    """Build the FMUs `names` into `folder` (one part of :func:`build_fmus`)."""
    from panto.build_fmu.project import build_project_fmus

    return build_project_fmus(folder, names=names, fmi_versions=fmi_versions,
                              progress=progress)


def run_rig_campaign(state: dict[str, Any], progress: Progress) -> dict:
    """Step 2a: the two runs on the virtual test bed, and the nominal model against each.

    The runs are independent: with ``settings.workers`` > 1 the second runs in a worker
    process beside the first (its progress lines follow when it ends); the recorded files are
    the same as one after the other (each run has its own bus, clock and noise seed).
    """
    out, settings = state["out"], state["settings"]
    jobs = [(label, file, seed, _new_run_folder(out, label)) for label, file, seed in CAMPAIGN]
    done = _side_by_side(_rig_run, [(out, state["fmus"], settings, *job) for job in jobs],
                         settings.workers, progress)
    labels = [label for label, *_ in jobs]
    runs = {label: run for label, (run, _) in zip(labels, done)}
    state["runs"] = {label: out / run["folder"] for label, run in runs.items()}
    nominal = {label: fits for label, (_, fits) in zip(labels, done)}
    return {"runs": runs, "nominal_model_fit_percent": nominal,
            "plots": {label: f"{label}_run.png" for label in runs}}


def _new_run_folder(out: Path, label: str) -> Path:
    from panto.rig.recorder import new_run_folder

    return new_run_folder(out / "runs", prefix=label)  # a rerun never overwrites a run


def _side_by_side(function: Callable[..., Any], jobs: list[tuple], workers: int,
                  progress: Progress) -> list[Any]:
    """``[function(*job, progress) for job in jobs]``, the first job here, the others in up to
    ``workers - 1`` worker processes at the same time (their progress lines follow at their end).
    """
    if workers <= 1 or len(jobs) < 2:
        return [function(*job, progress) for job in jobs]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=min(workers - 1, len(jobs) - 1)) as pool:
        futures = [pool.submit(_collecting, function, job) for job in jobs[1:]]
        results = [function(*jobs[0], progress)]
        for future in futures:
            result, lines = future.result()
            for line in lines:
                progress(line)
            results.append(result)
    return results


def _collecting(function: Callable[..., Any], job: tuple) -> tuple[Any, list[str]]:
    """``function(*job, progress)`` in a worker process, with its progress lines collected."""
    lines: list[str] = []
    return function(*job, lines.append), lines


def _rig_run(out: Path, fmus: Path, settings: Any, label: str, file: str, seed: int,
             folder: Path, progress: Progress) -> tuple[dict, dict]:
    """One run of the campaign into `folder` and the nominal model against it."""
    from dataclasses import replace
    from importlib.resources import files

    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    profile = load_profile(files("panto.rig") / "profiles" / file)
    if settings.run_duration:
        profile = replace(profile, duration=settings.run_duration)
    clock = time.perf_counter()
    result = run_virtual_profile(profile, fmu_path=fmus / "Pantograph.fmu", folder=folder,
                                 seed=seed, progress=progress)
    seconds = time.perf_counter() - clock
    progress(f"{label}: {profile.name}, {profile.duration:g} s in {seconds:.1f} s wall, "
             f"{result.status}")
    if not result.success:
        raise RuntimeError(f"the {label} run did not complete: {result.status}")
    run = {"profile": profile.name, "duration_s": profile.duration,
           "folder": str(folder.relative_to(out)), "wall_s": seconds}
    return run, _nominal_against_measured(out, label, folder, progress)


def _nominal_against_measured(out: Path, label: str, folder: Path, progress: Progress) -> dict:
    """Simulate the nominal nonlinear and linearised FMUs on a run's measured inputs."""
    from panto.build_fmu.simulate import FmuSimulator
    from panto.rig.dataset import read_dataset

    data = read_dataset(folder)
    zero = float(data.metadata.extra.get("rig_setup", {}).get("motor_zero_height", 2.0))
    inputs = {"eta": zero + data["motor_position"], "p": data["pressure"]}
    measured = {"F_c": data["force"], "y_cb": np.nanmean(
        np.vstack([data["laser_1"], data["laser_2"]]), axis=0)}
    responses = {}
    for name in ("Pantograph", "PantographLinear"):
        start = ({"eta0": float(inputs["eta"][0]), "p0": float(inputs["p"][0])}
                 if name == "PantographLinear" else None)
        with FmuSimulator(out / "fmus" / f"{name}.fmu", interface="CS") as simulator:
            responses[name] = simulator.simulate(data.time, inputs, start_values=start)
    fits = {name: {signal: fit_percent(measured[signal], np.asarray(responses[name][signal]))
                   for signal in measured} for name in responses}
    figure = plot_trajectories(data.time, inputs, zero, measured, responses,
                               title=f"{label} run (virtual test bed)")
    figure.savefig(out / f"{label}_run.png", dpi=110)
    progress(f"{label}: nominal model fit on force {fits['Pantograph']['F_c']:.1f} %, on cross "
             f"bar {fits['Pantograph']['y_cb']:.1f} % -> {label}_run.png")
    return fits


def plot_trajectories(t: np.ndarray, inputs: dict, zero: float, measured: dict, responses: dict,
                      *, title: str):
    """Inputs, measured outputs and the nominal FMUs' responses over time (one figure)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 9))
    axes = fig.subplots(4, 1, sharex=True)
    axes[0].plot(t, (inputs["eta"] - zero) * 1e3, color="k", lw=0.8)
    axes[0].set_ylabel("linear motor [mm]")
    axes[1].plot(t, inputs["p"], color="k", lw=0.8)
    axes[1].set_ylabel("pressure [bar]")
    styles = {"Pantograph": ("nominal model (FMU)", "-"),
              "PantographLinear": ("linearised FMU", "--")}
    for ax, name, scale, unit in ((axes[2], "y_cb", 1e3, "mm"), (axes[3], "F_c", 1.0, "N")):
        ax.plot(t, measured[name] * scale, color="0.55", lw=0.7, label="measured")
        for fmu, response in responses.items():
            ax.plot(response.time, np.asarray(response[name]) * scale, lw=0.9,
                    ls=styles[fmu][1], label=styles[fmu][0])
        ax.set_ylabel(f"{name} [{unit}]")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(f"{title}: measured vs the nominal pantograph model")
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: savefig draws once
    return fig


def film_runs(state: dict[str, Any], progress: Progress) -> dict:
    """Step 2b: film, track, synchronise and merge a window of each run (camera at reduced
    resolution, encoded with :data:`VIDEO_PRESET`: ~16 s of CPU per 30 s window at 960 x 540 on
    this machine, ``benchmarks/demo_filming_speed.md``).

    The runs are filmed side by side like :func:`run_rig_campaign` runs them when
    ``settings.workers`` > 1; :func:`panto.demo.run_demo` runs this step itself in a worker
    process beside the identification, with ``workers=1`` (one run after the other).
    """
    out, settings = state["out"], state["settings"]
    jobs = [(label, folder, out / "video", settings) for label, folder in state["runs"].items()]
    videos = dict(zip(state["runs"], _side_by_side(_film_one, jobs, settings.workers, progress)))
    state["merged"] = {label: Path(v["merged_dataset"]) for label, v in videos.items()}
    confidences = [v["sync_confidence"] for v in videos.values()]
    return {"runs": {k: {**v, "merged_dataset": str(Path(v["merged_dataset"]).relative_to(out))}
                     for k, v in videos.items()},
            "min_sync_confidence": float(min(confidences)),
            "camera": {"scale": settings.video_scale, "window_s": settings.video_window}}


def _film_one(label: str, folder: Path, video_dir: Path, settings: Any,
              progress: Progress) -> dict:
    from panto.video_sync.camera import CameraSetup, render_run
    from panto.video_sync.merge import sync_and_merge
    from panto.video_sync.setup import setup_from_camera
    from panto.video_sync.tracking import track_video

    video_dir.mkdir(parents=True, exist_ok=True)
    camera = CameraSetup().reduced(settings.video_scale) if settings.video_scale != 1 \
        else CameraSetup()
    clock = time.perf_counter()
    video = render_run(folder, video_dir / f"{label}.mp4", setup=camera, rng=7,
                       duration=settings.video_window, preset=VIDEO_PRESET, crf=VIDEO_CRF)
    rendered = time.perf_counter() - clock
    tracker = setup_from_camera(video.camera_json)
    tracker.save(video_dir / f"{label}_setup.json")
    track = track_video(video.path, tracker, workers=1)
    track_csv = video_dir / f"{label}_track.csv"
    track.to_csv(track_csv)
    merged_folder = folder / "video_merged"
    if (merged_folder / "run.csv").exists():
        (merged_folder / "run.csv").unlink()  # the step was rerun on the same run folder
    merged = sync_and_merge(folder, track_csv, merged_folder,
                            plot=video_dir / f"{label}_sync.png")
    agreement = _video_against_laser(merged.dataset)
    # Frame k shows the truth at run time start_time + k / fps (start_sample indexes truth.csv,
    # whose rows begin before the run's t = 0); the merge puts it at (shift + 1 + 10 k) samples.
    sample_period = 1.0 / float(merged.dataset.metadata.sample_rate)
    placed = (int(merged.sync.shift) + int(merged.dataset.metadata.extra["video_sync"]
                                           ["led_delay_samples"])) * sample_period
    error = int(round((placed - float(video.start_time)) / sample_period))
    seconds = time.perf_counter() - clock
    progress(f"{label}: {video.frame_count} frames {camera.width}x{camera.height} rendered in "
             f"{rendered:.1f} s; sync confidence {merged.sync.confidence:.3f}, shift "
             f"{merged.sync.shift} samples; video vs laser cross bar RMS "
             f"{agreement['rms_mm']:.2f} mm (offset {agreement['mean_mm']:+.2f} mm); against the "
             f"camera's truth the alignment is off by {error} samples ({seconds:.1f} s)")
    return {"video": str(video.path.name), "frames": video.frame_count,
            "resolution": [camera.width, camera.height], "render_s": rendered,
            "total_s": seconds, "sync_confidence": float(merged.sync.confidence),
            "peak_ratio": float(merged.sync.peak_ratio), "shift_samples": int(merged.sync.shift),
            "true_start_sample": int(video.start_sample), "sync_error_samples": error,
            "lost_frames": dict(track.lost_frames),
            "merged_dataset": str(merged.path), "merged_samples": len(merged.dataset),
            "video_vs_laser": agreement, "sync_plot": f"video/{label}_sync.png"}


def _video_against_laser(dataset: Any) -> dict:
    """RMS difference between the tracked cross-bar marker and the lasers' mean [mm]."""
    names = set(dataset.names)
    if "video_cross_bar_y" not in names:
        return {"rms_mm": float("nan"), "samples": 0, "note": "no cross_bar marker track"}
    video = np.asarray(dataset["video_cross_bar_y"], float)
    laser = np.nanmean(np.vstack([dataset["laser_1"], dataset["laser_2"]]), axis=0)
    ok = np.isfinite(video) & np.isfinite(laser)
    difference = video[ok] - laser[ok]
    return {"rms_mm": float(1e3 * np.sqrt(np.mean(difference ** 2))) if ok.any() else float("nan"),
            "mean_mm": float(1e3 * np.mean(difference)) if ok.any() else float("nan"),
            "std_mm": float(1e3 * np.std(difference)) if ok.any() else float("nan"),
            "samples": int(ok.sum())}
