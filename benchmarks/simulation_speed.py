"""Benchmark: simulation speed of the nonlinear pantograph (FMU CS, FMU ME, Python path) and the
time and memory of ``panto build-fmu``. Run by hand; writes benchmarks/results.json and .md.

    .venv/bin/python benchmarks/simulation_speed.py [--python-seconds 3]

The rig excitation is 60 s of APRBS on eta and p with outputs at 500 Hz (the shipped rig/profiles/aprbs_training.json, conditioned as the rig does).
The Python path (SciPy solve_ivp, LSODA with the exact Jacobian, restarted at every 500 Hz sample
like the FMU's communication steps) is too slow for 60 s, so it runs the first --python-seconds and
its speed is reported per simulated second.
"""
from __future__ import annotations

import argparse
import json
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))


def measure_build(out: Path) -> dict:
    """Wall time and peak memory of `panto build-fmu` in a fresh process (cold caches)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "panto.cli", "build-fmu", "--out", str(out)], check=True,
                   cwd=HERE.parent, capture_output=True)
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return {"wall_s": round(wall, 2), "peak_rss_mib": round(max(peak, before) / 1024, 1),
            "fmus": sorted(p.name for p in out.glob("*.fmu"))}


def rig_excitation(duration: float) -> tuple:
    """The shipped APRBS training profile: conditioned motor command and pressure demand, 500 Hz."""
    from dataclasses import replace
    from importlib.resources import files

    import numpy as np

    from panto.rig.profile_preview import conditioned_command
    from panto.rig.profiles import load_profile, render_profile

    profile = replace(load_profile(files("panto.rig") / "profiles" / "aprbs_training.json"),
                      duration=duration)
    rendered = render_profile(profile)
    stream_time, command = conditioned_command(profile)
    eta = 2.0 + np.interp(rendered.time, stream_time, command)
    return rendered.time, {"eta": eta, "p": rendered.pressure_demand}


def measure_simulation(fmus: Path, python_seconds: float) -> dict:
    from panto.build_fmu.simulate import FmuSimulator
    from panto.fmu_src.models import Model
    from panto.fmu_src.simulation import simulate_model
    t, inputs = rig_excitation(60.0)
    results = {}
    for interface in ("CS", "ME"):
        with FmuSimulator(fmus / "Pantograph.fmu", interface=interface) as simulator:
            simulator.simulate(t[:501], {k: v[:501] for k, v in inputs.items()})  # warm-up
            start = time.perf_counter()
            simulator.simulate(t, inputs)
            wall = time.perf_counter() - start
        results[f"fmu_{interface}"] = {"simulated_s": 60.0, "wall_s": round(wall, 3),
                                       "real_time_factor": round(60.0 / wall, 1)}
    model = Model("Pantograph")
    model.equilibrium(2.0, 4.0)  # compile the Python functions outside the timing
    model.linearise(2.0, 4.0)
    n = int(python_seconds * 500) + 1
    start = time.perf_counter()
    simulate_model(model, t[:n], {k: v[:n] for k, v in inputs.items()})
    wall = time.perf_counter() - start
    results["python_solve_ivp"] = {"simulated_s": python_seconds, "wall_s": round(wall, 3),
                                   "real_time_factor": round(python_seconds / wall, 3)}
    for interface in ("CS", "ME"):
        fmu = results[f"fmu_{interface}"]["real_time_factor"]
        results[f"fmu_{interface}"]["speedup_over_python"] = round(fmu / results["python_solve_ivp"]["real_time_factor"], 1)
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--python-seconds", type=float, default=3.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        fmus = Path(tmp) / "fmus"
        print("building the FMUs ...", flush=True)
        build = measure_build(fmus)
        print(f"  {build['wall_s']} s, peak {build['peak_rss_mib']} MiB", flush=True)
        print("simulating ...", flush=True)
        simulation = measure_simulation(fmus, args.python_seconds)
    report = {"date": time.strftime("%Y-%m-%d"), "machine": f"{platform.node()} {platform.processor()} "
              f"{platform.python_version()}", "build_fmu": build, "simulation_60s_rig_run": simulation}
    (HERE / "results.json").write_text(json.dumps(report, indent=2) + "\n")
    lines = ["| path | simulated [s] | wall [s] | real-time factor | speed-up over Python |",
             "|---|---|---|---|---|"]
    for name, r in simulation.items():
        lines.append(f"| {name} | {r['simulated_s']} | {r['wall_s']} | {r['real_time_factor']} | "
                     f"{r.get('speedup_over_python', '')} |")
    lines.append(f"\n`panto build-fmu` (8 FMUs, cold): {build['wall_s']} s wall, "
                 f"peak resident memory {build['peak_rss_mib']} MiB.")
    (HERE / "results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
