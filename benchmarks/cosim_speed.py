"""Benchmark: speed of the co-simulation (catenary + pantograph FMU through fmpy).

Run by hand; writes benchmarks/cosim_speed.json and benchmarks/cosim_speed.md.

    .venv/bin/python benchmarks/cosim_speed.py [--quick]

1. The EN 50318:2002 reference case at 250 km/h, the whole ten-span run (600 m, 8.64 s
   simulated), with the default settings (time step = communication step 5e-4 s, element length
   0.25 m) and with 2e-4 s and 1e-4 s: wall time against simulated time (goal: >= 1 simulated
   second per wall second, fmpy coupling included), where the time goes (catenary solve, FMU
   calls, Python loop), and the statistics of each (the time step's effect on the results).
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
            "python_s": round(timing["python"], 2),
            "us_per_step": {k: round(1e6 * timing[k] / steps, 1)
                            for k in ("catenary", "fmu", "python")},
            "steps": steps}


def reference_runs(fmus: Path, steps: list[float], say) -> list[dict]:
    from panto.catenary_cosim.master import cosimulate

    rows = []
    for step in steps:
        say(f"EN 50318 reference, 250 km/h, time step {step:g} s")
        result = cosimulate("en50318-2002", _setup(fmus), speed_kmh=250.0, time_step=step)
        rows.append({"time_step_s": step, **_row(result),
                     "statistics": {k: round(v, 2)
                                    for k, v in result.statistics().to_dict().items()}})
    return rows


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
             "| time step (s) | simulated (s) | wall (s) | simulated s per wall s | catenary "
             "µs/step | FMU µs/step | Python µs/step | mean | std | max | min | uplift (mm) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["reference"]:
        s, u = r["statistics"], r["us_per_step"]
        lines.append(f"| {r['time_step_s']:g} | {r['simulated_s']} | {r['wall_loop_s']} | "
                     f"**{r['simulated_per_wall']}** | {u['catenary']} | {u['fmu']} | "
                     f"{u['python']} | {s['mean']} | {s['std']} | {s['max']} | {s['min']} | "
                     f"{s['uplift_max_mm']} |")
    lines += ["", "Wall time excludes the set-up (mesh, static state, factorisation, FMU "
              "instantiation: "
              f"{report['reference'][0]['wall_setup_s']} s).", "",
              "## Cost growth (one span, 60 m, at 250 km/h, default time step 5e-4 s)", "",
              "| spans | catenary µs/step | FMU µs/step | Python µs/step | simulated s per "
              "wall s |", "|---|---|---|---|---|"]
    for r in report["scaling"]["spans"]:
        u = r["us_per_step"]
        lines.append(f"| {r['spans']} | {u['catenary']} | {u['fmu']} | {u['python']} | "
                     f"{r['simulated_per_wall']} |")
    lines += ["", "| element length (m) | unknowns | catenary µs/step | FMU µs/step | "
              "Python µs/step | simulated s per wall s |", "|---|---|---|---|---|---|"]
    for r in report["scaling"]["element_length"]:
        u = r["us_per_step"]
        lines.append(f"| {r['element_length_m']} | {r['unknowns']} | {u['catenary']} | "
                     f"{u['fmu']} | {u['python']} | {r['simulated_per_wall']} |")
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
                  "scaling": scaling(fmus, spans, elements, say)}
    (HERE / "cosim_speed.json").write_text(json.dumps(report, indent=2) + "\n")
    (HERE / "cosim_speed.md").write_text(render(report))
    say(render(report))


if __name__ == "__main__":
    main()
