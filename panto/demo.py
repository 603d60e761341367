"""The main job (``panto demo``), as far as the product goes today.

1. Generate, compile, package and validate the FMUs (FMI 2.0 and 3.0, ME and CS).
2. Run the thesis' rig campaign on the virtual test bed: an APRBS training run and a ramp
   validation run, through the CAN driver and the drive emulator, with the rig's imperfections
   on; the datasets (CSV, Parquet, MAT) go to ``runs/``.
3. Simulate the nominal nonlinear and linearised FMUs on each run's measured inputs and plot them
   against the measured force and cross-bar position (the sim-to-real gap before any fitting).

The rig, identification, diagnosis, design-of-experiments and catenary steps of the full story
(issue 9) join here as those parts land.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable

import numpy as np

def _fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Fit % = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) (thesis section 4.1.3)."""
    return float(100 * (1 - np.linalg.norm(measured - simulated)
                        / np.linalg.norm(measured - measured.mean())))


def run_demo(out: Path, *, quick: bool = False, progress: Callable[[str], None] = print) -> dict:
    """Run the main job and write its results to ``out``; returns the summary."""
    from build_fmu.project import build_project_fmus
    from fmu_src.models import Model

    started = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    progress(f"[1/3] building the FMUs into {out / 'fmus'}")
    names = ("Pantograph", "PantographLinear") if quick else None
    kwargs = {"names": names} if names else {}
    built = build_project_fmus(out / "fmus", progress=lambda s: progress("      " + s), **kwargs)
    invalid = [b.path.name for b in built if b.problems]
    if invalid:
        raise RuntimeError(f"fmpy's validator rejected {invalid}")

    progress("[2/3] rig campaign on the virtual test bed (CAN driver + drive emulator, "
             "imperfections on)")
    runs = _rig_campaign(out, quick=quick, progress=progress)

    progress("[3/3] the nominal model on the measured inputs (first look at the sim-to-real gap)")
    gap = {}
    for label, run in runs.items():
        gap[label] = _nominal_against_measured(out, label, run["folder"], progress)
    model = Model("Pantograph")
    lin = model.linearise(2.0, 4.0)
    summary = {
        "fmus": [{"file": b.path.name, "fmi_version": b.fmi_version, "valid": not b.problems}
                 for b in built],
        "rig_runs": runs,
        "nominal_model_fit_percent": gap,
        "check_point_eta2_p4": {"F_c_N": float(lin.y0[2]), "phi1_deg": float(np.degrees(lin.x0[0])),
                                "modes_hz": lin.natural_frequencies_hz.tolist()},
        "wall_time_s": time.perf_counter() - started,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    progress(f"done in {summary['wall_time_s']:.1f} s: {out / 'summary.json'}")
    return summary


def _rig_campaign(out: Path, *, quick: bool, progress: Callable[[str], None]) -> dict:
    """The thesis' two runs (APRBS training, ramp validation) on the virtual test bed."""
    from dataclasses import replace
    from importlib.resources import files

    from rig.profiles import load_profile
    from rig.recorder import new_run_folder
    from rig.virtual import run_virtual_profile

    runs = {}
    for label, file, quick_duration in (("training", "aprbs_training.json", 8.0),
                                        ("validation", "ramps_validation.json", 8.0)):
        profile = load_profile(files("rig") / "profiles" / file)
        if quick:
            profile = replace(profile, duration=quick_duration)
        folder = new_run_folder(out / "runs", prefix=label)  # a rerun never overwrites a run
        clock = time.perf_counter()
        result = run_virtual_profile(profile, fmu_path=out / "fmus" / "Pantograph.fmu",
                                     folder=folder, seed=1 if label == "training" else 2,
                                     progress=lambda s: progress("      " + s))
        seconds = time.perf_counter() - clock
        progress(f"      {label}: {profile.name}, {profile.duration:g} s in {seconds:.1f} s wall, "
                 f"{result.status}")
        if not result.success:
            raise RuntimeError(f"the {label} run did not complete: {result.status}")
        runs[label] = {"profile": profile.name, "duration_s": profile.duration,
                       "folder": str(folder.relative_to(out)), "wall_s": seconds}
    return runs


def _nominal_against_measured(out: Path, label: str, folder: str,
                              progress: Callable[[str], None]) -> dict:
    """Simulate the nominal nonlinear and linearised FMUs on a run's measured inputs."""
    from build_fmu.simulate import FmuSimulator
    from rig.dataset import read_dataset

    data = read_dataset(out / folder)
    inputs = {"eta": 2.0 + data["motor_position"], "p": data["pressure"]}
    measured = {"F_c": data["force"], "y_cb": 0.5 * (data["laser_1"] + data["laser_2"])}
    responses = {}
    for name in ("Pantograph", "PantographLinear"):
        with FmuSimulator(out / "fmus" / f"{name}.fmu", interface="CS") as simulator:
            responses[name] = simulator.simulate(data.time, inputs,
                                                 start_values={"eta0": 2.0 + data["motor_position"][0],
                                                               "p0": data["pressure"][0]}
                                                 if name == "PantographLinear" else None)
    fits = {name: {signal: _fit_percent(measured[signal], responses[name][signal])
                   for signal in measured} for name in responses}
    figure = _plot(data.time, inputs, measured, responses["Pantograph"],
                   responses["PantographLinear"], title=f"{label} run (virtual test bed)")
    figure.savefig(out / f"{label}_run.png", dpi=120)
    progress(f"      {label}: nominal model fit on force {fits['Pantograph']['F_c']:.1f} %, "
             f"on cross bar {fits['Pantograph']['y_cb']:.1f} % -> {label}_run.png")
    return fits


def _plot(t, inputs, measured, nonlinear, linear, *, title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 1, figsize=(11, 9), sharex=True)
    axes[0].plot(t, (inputs["eta"] - 2.0) * 1e3, color="k", lw=0.8)
    axes[0].set_ylabel("linear motor [mm]")
    axes[1].plot(t, inputs["p"], color="k", lw=0.8)
    axes[1].set_ylabel("pressure [bar]")
    for ax, name, scale, unit in ((axes[2], "y_cb", 1e3, "mm"), (axes[3], "F_c", 1.0, "N")):
        ax.plot(t, measured[name] * scale, color="0.55", lw=0.7, label="measured")
        ax.plot(nonlinear.time, nonlinear[name] * scale, lw=0.9, label="nominal model (FMU)")
        ax.plot(linear.time, linear[name] * scale, lw=0.9, ls="--", label="linearised FMU")
        ax.set_ylabel(f"{name} [{unit}]")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(f"{title}: measured vs the nominal pantograph model")
    fig.tight_layout()
    return fig
