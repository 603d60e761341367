"""The main job (``panto demo``), as far as the product goes today.

1. Generate, compile, package and validate the FMUs (FMI 2.0 and 3.0, ME and CS).
2. Excite the nonlinear and the linearised pantograph FMU with a rig-like run (APRBS on the
   linear motor height eta and on the bellow pressure p, 500 Hz), through fmpy in Co-Simulation.
3. Write the time series (CSV), a plot (PNG) and a summary (JSON) to the output folder.

The rig, identification, diagnosis, design-of-experiments and catenary steps of the full story
(issue 9) join here as those parts land.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable

import numpy as np

SAMPLE_RATE_HZ = 500.0


def generate_aprbs(rng: np.random.Generator, n_samples: int, sample_rate: float, *,
                   low: float, high: float, min_hold: float, max_hold: float) -> np.ndarray:
    """Amplitude-modulated pseudo-random binary sequence: random levels held for random times.

    Levels are uniform in [low, high]; hold times uniform in [min_hold, max_hold] seconds.
    (A placeholder for the rig's signal library, issue 4.)
    """
    signal = np.empty(n_samples)
    k = 0
    while k < n_samples:
        hold = int(round(rng.uniform(min_hold, max_hold) * sample_rate))
        signal[k:k + max(hold, 1)] = rng.uniform(low, high)
        k += max(hold, 1)
    return signal


def rig_excitation(duration: float, *, seed: int = 1) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A rig-like run: APRBS on eta (2.0 m +- 25 mm) and p (3.6-4.6 bar), 500 Hz, smoothed.

    The linear-motor height is low-pass filtered (as the rig's reference filter does) so that the
    commanded position has no jumps; the pressure follows the bellow's first-order lag (~0.3 s).
    """
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    n = int(round(duration * SAMPLE_RATE_HZ)) + 1
    t = np.arange(n) / SAMPLE_RATE_HZ
    eta = generate_aprbs(rng, n, SAMPLE_RATE_HZ, low=1.975, high=2.025, min_hold=0.2, max_hold=1.5)
    p = generate_aprbs(rng, n, SAMPLE_RATE_HZ, low=3.6, high=4.6, min_hold=1.0, max_hold=4.0)

    def first_order(x: np.ndarray, tau: float) -> np.ndarray:
        a = np.exp(-1.0 / (tau * SAMPLE_RATE_HZ))
        return lfilter([1 - a], [1, -a], x, zi=[a * x[0]])[0]

    eta = first_order(first_order(eta, 0.03), 0.03)
    return t, {"eta": eta, "p": first_order(p, 0.3)}


def _fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """Fit % = 100 (1 - ||y - y_hat|| / ||y - mean(y)||) (thesis section 4.1.3)."""
    return float(100 * (1 - np.linalg.norm(measured - simulated)
                        / np.linalg.norm(measured - measured.mean())))


def run_demo(out: Path, *, quick: bool = False, progress: Callable[[str], None] = print) -> dict:
    """Run the main job and write its results to ``out``; returns the summary."""
    from build_fmu.project import build_project_fmus
    from build_fmu.simulate import FmuSimulator
    from fmu_src.models import Model

    started = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    progress(f"[1/3] building the FMUs into {out / 'fmus'}")
    names = ("Pantograph", "PantographLinear") if quick else None
    kwargs = {"names": names} if names else {}
    built = build_project_fmus(out / "fmus", progress=lambda s: progress("      " + s), **kwargs)
    invalid = [b.path.name for b in built if b.problems]

    duration = 10.0 if quick else 60.0
    progress(f"[2/3] simulating a {duration:.0f} s rig run (APRBS on eta and p, 500 Hz)")
    t, inputs = rig_excitation(duration)
    responses = {}
    for name in ("Pantograph", "PantographLinear"):
        clock = time.perf_counter()
        with FmuSimulator(out / "fmus" / f"{name}.fmu", interface="CS") as simulator:
            responses[name] = simulator.simulate(t, inputs)
        progress(f"      {name}.fmu (CS): {time.perf_counter() - clock:.2f} s wall for {duration:.0f} s")

    progress("[3/3] writing the time series, the plot and the summary")
    nonlinear, linear = responses["Pantograph"], responses["PantographLinear"]
    csv_path = nonlinear.to_csv(out / "pantograph_rig_run.csv")
    figure = _plot(t, inputs, nonlinear, linear)
    figure.savefig(out / "pantograph_rig_run.png", dpi=120)
    model = Model("Pantograph")
    lin = model.linearise(2.0, 4.0)
    summary = {
        "fmus": [{"file": b.path.name, "fmi_version": b.fmi_version, "valid": not b.problems}
                 for b in built],
        "invalid_fmus": invalid,
        "rig_run": {"duration_s": duration, "sample_rate_hz": SAMPLE_RATE_HZ, "csv": csv_path.name,
                    "plot": "pantograph_rig_run.png"},
        "linear_vs_nonlinear_fit_percent": {
            name: _fit_percent(nonlinear[name], linear[name]) for name in ("y_cb", "xi", "F_c")},
        "check_point_eta2_p4": {"F_c_N": float(lin.y0[2]), "phi1_deg": float(np.degrees(lin.x0[0])),
                                "modes_hz": lin.natural_frequencies_hz.tolist()},
        "wall_time_s": time.perf_counter() - started,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    progress(f"done in {summary['wall_time_s']:.1f} s: {out / 'summary.json'}")
    if invalid:
        raise RuntimeError(f"fmpy's validator rejected {invalid}")
    return summary


def _plot(t, inputs, nonlinear, linear):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 1, figsize=(11, 9), sharex=True)
    axes[0].plot(t, inputs["eta"] * 1e3, color="k", lw=0.8)
    axes[0].set_ylabel("eta [mm]")
    axes[1].plot(t, inputs["p"], color="k", lw=0.8)
    axes[1].set_ylabel("p [bar]")
    for ax, name, scale, unit in ((axes[2], "y_cb", 1e3, "mm"), (axes[3], "F_c", 1.0, "N")):
        ax.plot(nonlinear.time, nonlinear[name] * scale, lw=0.9, label="nonlinear FMU")
        ax.plot(linear.time, linear[name] * scale, lw=0.9, ls="--", label="linearised FMU")
        ax.set_ylabel(f"{name} [{unit}]")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title("Pantograph on a rig-like run: nonlinear vs linearised FMU (Co-Simulation)")
    fig.tight_layout()
    return fig
