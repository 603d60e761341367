"""Benchmark: speed of the co-simulation (catenary + pantograph FMU through fmpy).

Run by hand; writes benchmarks/cosim_speed.json and benchmarks/cosim_speed.md.

    .venv/bin/python benchmarks/cosim_speed.py [--quick]

1. The EN 50318:2002 reference case at 250 km/h, the whole ten-span run (600 m, 8.64 s
   simulated), with the default settings (time step = communication step 5e-4 s, element length
   0.25 m) and with 2e-4 s and 1e-4 s: wall time against simulated time (goal: >= 10 simulated
   seconds per wall second, fmpy coupling included), the same per CPU second of the process
   (what a busy machine does not take away), where the time goes (catenary step, FMU calls,
   Python loop), and the statistics of each (the time step's effect on the results). The
   default case runs three times: the loop in C (`panto.catenary_cosim.coupling_kernel`, the
   FMU's FMI functions called directly) on the compiled step (`panto.catenary_cosim.kernel`),
   the Python loop through fmpy on the same step, and the Python loop on the NumPy/LAPACK step
   (``PANTO_CATENARY_KERNEL=0``).
   Beside it, in the same process, the pure-arithmetic reference: one pre-factorised banded
   Cholesky solve (LAPACK ``dpbtrs``) of the same 4798-unknown matrix, the least any step that
   solves the system with LAPACK must cost.
2. How the cost per simulated second grows with the number of spans (2 ... 10, element 0.25 m)
   and with mesh refinement (element 1.0 ... 0.125 m, ten spans), each over one span (60 m).

The machine load is recorded: other processes on the same cores slow everything down.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))


def _setup(fmus: Path):
    from panto.catenary_cosim.pantographs import pantograph_setup

    return pantograph_setup("en50318-2002").with_fmu(fmus / "TwoMass.fmu")


def _row(result) -> dict:
    timing, simulated = result.timing, float(result.time[-1])
    steps = result.counters["communication_steps"]
    return {"simulated_s": round(simulated, 3), "wall_loop_s": round(timing["loop"], 2),
            "wall_setup_s": round(timing["setup"], 2),
            "simulated_per_wall": round(simulated / timing["loop"], 2),
            "catenary_s": round(timing["catenary"], 2), "fmu_s": round(timing["fmu"], 2),
            "python_s": round(timing["python"], 2), "cpu_loop_s": round(timing["loop_cpu"], 2),
            "simulated_per_cpu": round(simulated / timing["loop_cpu"], 2),
            "load_1min": round(os.getloadavg()[0], 1),
            "us_per_step": {k: round(1e6 * timing[k] / steps, 1)
                            for k in ("catenary", "fmu", "python")},
            "steps": steps}


#: (catenary step, loop) of the default case: the C loop, the Python loop through fmpy on the
#: same compiled step, and the Python loop on the NumPy/LAPACK step.
VARIANTS = (("compiled", True), ("compiled", False), ("numpy", False))


def reference_runs(fmus: Path, steps: list[float], say) -> list[dict]:
    from panto.catenary_cosim.catenary import Catenary

    rows = []
    for step in steps:
        for backend, compiled in (VARIANTS if step == steps[0] else VARIANTS[:1]):
            say(f"EN 50318 reference, 250 km/h, time step {step:g} s, {backend} step, "
                f"{'C' if compiled else 'Python'} loop")
            os.environ["PANTO_CATENARY_KERNEL"] = "1" if backend == "compiled" else "0"
            catenary = Catenary(_line(), time_step=step)
            result, cpu = _timed_run_catenary(fmus, catenary, compiled)
            rows.append({"time_step_s": step, "backend": catenary._integrator.backend,
                         "loop": result.settings["loop"], **_row(result), **cpu,
                         "statistics": {k: round(v, 2)
                                        for k, v in result.statistics().to_dict().items()}})
    os.environ.pop("PANTO_CATENARY_KERNEL", None)
    return rows


def _line():
    from panto.catenary_cosim.lines import load_line

    return load_line("en50318-2002")


def _timed_run_catenary(fmus: Path, catenary, compiled_loop: bool = True):
    """A run on a ready catenary and the CPU seconds of this process over the whole call."""
    from panto.catenary_cosim.master import cosimulate

    cpu = time.process_time()
    result = cosimulate(catenary, _setup(fmus), speed_kmh=250.0, compiled_loop=compiled_loop)
    return result, {"cpu_call_s": round(time.process_time() - cpu, 2)}


def arithmetic_reference(say) -> dict:
    """One pre-factorised LAPACK banded solve (dpbtrs) of the default run's matrix, and the
    compiled step alone, per call (best of 20 batches of 200; wall and CPU time)."""
    import numpy as np
    from scipy.linalg import lapack

    from panto.catenary_cosim.catenary import Catenary

    say("pure-arithmetic reference: dpbtrs of the same matrix")
    catenary = Catenary(_line(), time_step=5e-4)
    factor = catenary._integrator.solver.factor._factor
    rhs = np.random.default_rng(0).standard_normal(catenary.mesh.unknowns)

    def best(call) -> dict:
        call()
        wall, cpu = [], []
        for _ in range(20):
            w0, c0 = time.perf_counter(), time.process_time()
            for _ in range(200):
                call()
            wall.append((time.perf_counter() - w0) / 200)
            cpu.append((time.process_time() - c0) / 200)
        return {"wall_us": round(1e6 * min(wall), 1), "cpu_us": round(1e6 * min(cpu), 1)}

    return {"unknowns": int(catenary.mesh.unknowns),
            "dpbtrs": best(lambda: lapack.dpbtrs(factor, rhs, lower=0)),
            "step": best(lambda: catenary.advance(120.0, 300.0)),
            "backend": catenary._integrator.backend}


def scaling(fmus: Path, spans: list[int], elements: list[float], say) -> dict:
    from panto.catenary_cosim.lines import load_line
    from panto.catenary_cosim.master import cosimulate

    base = load_line("en50318-2002")
    rows = {"spans": [], "element_length": []}
    for count in spans:
        line = dataclasses.replace(base, spans=count, analysed_spans=(1, count))
        say(f"scaling: {count} spans")
        result = cosimulate(line, _setup(fmus), speed_kmh=250.0, stop_position=60.0)
        rows["spans"].append({"spans": count, **_row(result)})
    for length in elements:
        say(f"scaling: element length {length} m")
        result = cosimulate(base, _setup(fmus), speed_kmh=250.0, element_length=length,
                            stop_position=60.0)
        rows["element_length"].append({"element_length_m": length,
                                       "unknowns": _unknowns(base, length), **_row(result)})
    return rows


def _unknowns(line, length: float) -> int:
    from panto.catenary_cosim.catenary import Catenary

    return int(Catenary(line, time_step=5e-4, element_length=length).mesh.unknowns)


def render(report: dict) -> str:
    lines = ["# Co-simulation speed", "",
             f"Machine: {report['machine']['processor'] or report['machine']['platform']}, "
             f"{report['machine']['cpus']} CPUs, load average before the runs "
             f"{report['machine']['load_before']} (other work on the same cores slows the runs).",
             "", "## EN 50318:2002 reference case, 250 km/h, ten spans (600 m)", "",
             "| time step (s) | step | loop | simulated (s) | wall (s) | CPU (s) | simulated s "
             "per wall s | simulated s per CPU s | load (1 min) | catenary µs/step | FMU µs/step | "
             "Python µs/step | mean | std | max | min | uplift (mm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["reference"]:
        s, u = r["statistics"], r["us_per_step"]
        lines.append(f"| {r['time_step_s']:g} | {r['backend']} | {r['loop']} | "
                     f"{r['simulated_s']} | {r['wall_loop_s']} | {r['cpu_loop_s']} | "
                     f"**{r['simulated_per_wall']}** | **{r['simulated_per_cpu']}** | "
                     f"{r['load_1min']} | {u['catenary']} | {u['fmu']} | "
                     f"{u['python']} | {s['mean']} | {s['std']} | {s['max']} | {s['min']} | "
                     f"{s['uplift_max_mm']} |")
    a = report["arithmetic"]
    lines += ["", "Wall and CPU time are the loop's (this process' CPU seconds), without the "
              "set-up (mesh, static state, factorisation, FMU instantiation: "
              f"{report['reference'][0]['wall_setup_s']} s wall). The per-part timers are wall "
              "time: on a loaded machine they include the time the process waited for a core. "
              f"Load average after the runs {report['machine']['load_after']}.", "",
              f"Pure-arithmetic reference in the same process ({a['unknowns']} unknowns, best "
              "of 20 batches of 200 calls): one pre-factorised LAPACK banded Cholesky solve "
              f"(`dpbtrs`) {a['dpbtrs']['wall_us']} µs wall / {a['dpbtrs']['cpu_us']} µs CPU; "
              f"one whole catenary step (`Catenary.advance`, {a['backend']}) "
              f"{a['step']['wall_us']} µs wall / {a['step']['cpu_us']} µs CPU.", "",
              "## Cost growth (one span, 60 m, at 250 km/h, default time step 5e-4 s)", "",
              "| spans | catenary µs/step | FMU µs/step | Python µs/step | simulated s per "
              "wall s | simulated s per CPU s |", "|---|---|---|---|---|---|"]
    for r in report["scaling"]["spans"]:
        u = r["us_per_step"]
        lines.append(f"| {r['spans']} | {u['catenary']} | {u['fmu']} | {u['python']} | "
                     f"{r['simulated_per_wall']} | {r['simulated_per_cpu']} |")
    lines += ["", "| element length (m) | unknowns | catenary µs/step | FMU µs/step | "
              "Python µs/step | simulated s per wall s | simulated s per CPU s |",
              "|---|---|---|---|---|---|---|"]
    for r in report["scaling"]["element_length"]:
        u = r["us_per_step"]
        lines.append(f"| {r['element_length_m']} | {r['unknowns']} | {u['catenary']} | "
                     f"{u['fmu']} | {u['python']} | {r['simulated_per_wall']} | "
                     f"{r['simulated_per_cpu']} |")
    lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="default time step only, fewer "
                        "scaling points")
    args = parser.parse_args()
    from panto.build_fmu.project import build_project_fmus

    say = lambda text: print(text, flush=True)  # noqa: E731
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as folder:
        build_project_fmus(folder, names=["TwoMass"], fmi_versions=(2,))
        fmus = Path(folder)
        steps = [5e-4] if args.quick else [5e-4, 2e-4, 1e-4]
        spans = [2, 10] if args.quick else [2, 4, 6, 8, 10]
        elements = [1.0, 0.25] if args.quick else [1.0, 0.5, 0.25, 0.125]
        report = {"machine": {"platform": platform.platform(), "processor": platform.processor(),
                              "cpus": os.cpu_count(),
                              "load_before": [round(x, 2) for x in load]},
                  "reference": reference_runs(fmus, steps, say),
                  "arithmetic": arithmetic_reference(say),
                  "scaling": scaling(fmus, spans, elements, say)}
        report["machine"]["load_after"] = [round(x, 2) for x in os.getloadavg()]
    (HERE / "cosim_speed.json").write_text(json.dumps(report, indent=2) + "\n")
    (HERE / "cosim_speed.md").write_text(render(report))
    say(render(report))


if __name__ == "__main__":
    main()
