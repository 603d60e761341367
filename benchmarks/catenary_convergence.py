"""Benchmark: mesh and time-step convergence and cost of the finite-difference catenary.

Run by hand; writes benchmarks/catenary_convergence.json and .md.

    .venv/bin/python benchmarks/catenary_convergence.py [--quick]

* Convergence: the EN 50318:2002 line (ten 60 m spans) under a constant 120 N moving at 250 km/h
  from the first support to the end of the analysed spans (5 and 6). The contact-point uplift
  (wire height minus pre-state height under the force, sampled every 2 ms over the analysed
  spans) and the largest support uplift there are compared with the finest run
  (h = 0.125 m, dt = 0.25 ms): element lengths 1, 0.5, 0.25, 0.125 m at dt = 0.25 ms, and time
  steps 2, 1, 0.5, 0.25 ms at h = 0.125 m.
* Cost: microseconds per `Catenary.advance` + `contact_wire_height` for 2-20 spans and three
  element lengths, and the whole ten-span run at 250 km/h with dt = 1 ms and the default mesh
  (the catenary's share of the co-simulation).
* The pre-state: dropper lengths of one span (and the 2015 benchmark's against its published
  ones) and the EN 50318-style elasticity curve of span 5.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

from panto.catenary_cosim.catenary import DEFAULT_ELEMENT_LENGTH, Catenary  # noqa: E402
from panto.catenary_cosim.lines import load_line  # noqa: E402

FORCE, SPEED = 120.0, 250 / 3.6
SAMPLE = 0.002  # [s]


def moving_force_run(line, element_length: float, time_step: float) -> dict:
    """Contact-point uplift over the analysed spans and the largest support uplift there."""
    catenary = Catenary(line, time_step=time_step, element_length=element_length)
    low, high = line.analysed_section
    every = int(round(SAMPLE / time_step))
    inside = (catenary.support_positions >= low - 1e-9) & (catenary.support_positions <= high + 1e-9)
    uplift, support_max = [], 0.0
    start = time.perf_counter()
    for i in range(int(high / SPEED / time_step)):
        x = SPEED * (i + 1) * time_step
        catenary.advance(FORCE, x)
        if (i + 1) % every == 0 and x >= low:
            uplift.append(catenary.contact_wire_height(x) - catenary.static_contact_wire_height(x))
        support_max = max(support_max, float(catenary.support_uplift()[inside].max()))
    return {"element_length": catenary.element_length, "time_step": time_step,
            "uplift": np.array(uplift), "support_uplift_max": support_max,
            "wall_s": time.perf_counter() - start}


def compare(runs: list[dict], reference: dict) -> list[dict]:
    rows = []
    for run in runs:
        n = min(len(run["uplift"]), len(reference["uplift"]))
        error = run["uplift"][:n] - reference["uplift"][:n]
        rows.append({"element_length_m": run["element_length"], "time_step_ms": 1e3 * run["time_step"],
                     "uplift_max_mm": 1e3 * float(run["uplift"].max()),
                     "uplift_min_mm": 1e3 * float(run["uplift"].min()),
                     "support_uplift_max_mm": 1e3 * run["support_uplift_max"],
                     "error_max_mm": 1e3 * float(np.abs(error).max()),
                     "error_rms_mm": 1e3 * float(np.sqrt(np.mean(error**2))),
                     "support_error_mm": 1e3 * abs(run["support_uplift_max"]
                                                   - reference["support_uplift_max"]),
                     "wall_s": round(run["wall_s"], 2)})
    return rows


def convergence(line, quick: bool, say) -> dict:
    lengths = (1.0, 0.5, 0.25) if quick else (1.0, 0.5, 0.25, 0.125)
    steps = (2e-3, 1e-3, 5e-4) if quick else (2e-3, 1e-3, 5e-4, 2.5e-4)
    fine_h, fine_dt = lengths[-1], steps[-1]
    say(f"reference run h = {fine_h} m, dt = {1e3 * fine_dt} ms")
    reference = moving_force_run(line, fine_h, fine_dt)
    mesh_runs = []
    for h in lengths[:-1]:
        say(f"mesh h = {h} m")
        mesh_runs.append(moving_force_run(line, h, fine_dt))
    step_runs = []
    for dt in steps[:-1]:
        say(f"time step {1e3 * dt} ms")
        step_runs.append(moving_force_run(line, fine_h, dt))
    return {"reference": {"element_length_m": fine_h, "time_step_ms": 1e3 * fine_dt},
            "mesh": compare(mesh_runs + [reference], reference),
            "time_step": compare(step_runs + [reference], reference)}


def cost(line, quick: bool, say) -> list[dict]:
    rows = []
    for spans in ((2, 10) if quick else (2, 5, 10, 20)):
        variant = dataclasses.replace(line, spans=spans, analysed_spans=(1, spans))
        for h in (0.5, 0.25, 0.125):
            start = time.perf_counter()
            catenary = Catenary(variant, time_step=1e-3, element_length=h)
            build = time.perf_counter() - start
            steps = min(2000, int(catenary.length / SPEED / 1e-3) - 1)
            wall, cpu = drive(catenary, steps)
            rows.append({"spans": spans, "element_length_m": h,
                         "unknowns": catenary.mesh.unknowns, "build_s": round(build, 3),
                         "us_per_step": round(1e6 * wall / steps, 1),
                         "cpu_us_per_step": round(1e6 * cpu / steps, 1)})
            say(f"cost {spans} spans, h = {h} m: {1e6 * wall / steps:.0f} us/step "
                f"({1e6 * cpu / steps:.0f} us CPU)")
    return rows


def drive(catenary: Catenary, steps: int) -> tuple[float, float]:
    """Wall and CPU seconds of ``steps`` steps of the moving force (dt = 1 ms)."""
    wall, cpu = time.perf_counter(), time.process_time()
    for i in range(steps):
        x = SPEED * (i + 1) * 1e-3
        catenary.advance(FORCE, x)
        catenary.contact_wire_height(x)
    return time.perf_counter() - wall, time.process_time() - cpu


def whole_run(line) -> dict:
    catenary = Catenary(line, time_step=1e-3)
    steps = int(catenary.length / SPEED / 1e-3)
    wall, cpu = drive(catenary, steps)
    return {"line": line.name, "element_length_m": catenary.element_length, "time_step_ms": 1.0,
            "steps": steps, "simulated_s": round(steps * 1e-3, 3), "wall_s": round(wall, 3),
            "us_per_step": round(1e6 * wall / steps, 1),
            "cpu_us_per_step": round(1e6 * cpu / steps, 1),
            "real_time_factor": round(steps * 1e-3 / wall, 2),
            "real_time_factor_cpu": round(steps * 1e-3 / cpu, 2)}


def prestate() -> dict:
    out = {}
    for name in ("en50318-2002", "benchmark-2015"):
        line = load_line(name)
        catenary = Catenary(line, time_step=1e-3)
        n = len(line.dropper_positions)
        middle = line.spans // 2
        span = slice(middle * n, (middle + 1) * n)
        state = catenary.static_state
        out[name] = {"dropper_positions_in_span_m": list(line.dropper_positions),
                     "dropper_lengths_m": np.round(state.dropper_lengths[span], 4).tolist(),
                     "dropper_forces_N": np.round(state.dropper_forces[span], 2).tolist(),
                     "published_lengths_m": list(line.dropper_nominal_lengths or []),
                     "steady_arm_preload_N": round(float(state.steady_arm_forces[middle - 1]), 2),
                     "messenger_support_preload_N":
                         round(float(state.messenger_support_forces[middle - 1]), 1)}
        x = middle * line.span_length + np.arange(0.0, line.span_length + 0.01, 0.5)
        elasticity = catenary.elasticity(x)
        out[name]["elasticity"] = {
            "x_in_span_m": (x - x[0]).tolist(), "mm_per_N": np.round(1e3 * elasticity, 4).tolist(),
            "at_support_mm_per_N": round(1e3 * float(elasticity[0]), 4),
            "at_mid_span_mm_per_N": round(1e3 * float(np.interp(x[0] + line.span_length / 2, x,
                                                                 elasticity)), 4),
            "max_mm_per_N": round(1e3 * float(elasticity.max()), 4),
            "x_of_max_m": float(x[np.argmax(elasticity)] - x[0]),
            "min_mm_per_N": round(1e3 * float(elasticity.min()), 4),
            "x_of_min_m": float(x[np.argmin(elasticity)] - x[0]),
            "uniformity_pct": round(100 * float((elasticity.max() - elasticity.min())
                                                / (elasticity.max() + elasticity.min())), 1)}
    return out


def table(rows: list[dict], keys: list[str]) -> str:
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append("| " + " | ".join(_cell(row[k]) for k in keys) + " |")
    return "\n".join(lines)


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def write_markdown(results: dict, path: Path) -> None:
    conv, pre = results["convergence"], results["prestate"]
    keys = ["element_length_m", "time_step_ms", "uplift_max_mm", "uplift_min_mm",
            "support_uplift_max_mm", "error_max_mm", "error_rms_mm", "support_error_mm", "wall_s"]
    run = results["whole_run"]
    parts = [
        "# Finite-difference catenary: convergence and cost",
        f"Produced by `benchmarks/catenary_convergence.py` on {results['machine']}.",
        "Load: constant 120 N moving at 250 km/h along the EN 50318:2002 line (ten 60 m spans), "
        "from the first support to the end of the analysed spans 5-6. Uplift = contact-wire "
        "height minus pre-state height at the contact point, sampled every 2 ms over the analysed "
        "spans; errors against the finest run "
        f"(h = {conv['reference']['element_length_m']} m, "
        f"dt = {conv['reference']['time_step_ms']} ms).",
        "Reading: the time-step error is second order (average-acceleration Newmark). The mesh "
        "error at the contact point is first order in h: under a point force the wire has a kink "
        "(slope jump F/T) that the linear shape functions cut off between two nodes by "
        "F h xi (1 - xi) / T, up to F h / (4 T) = 0.375 mm for 120 N and h = 0.25 m on the "
        "contact wire (20 kN); this is a local read-out error that a 20 Hz low-pass of the "
        "contact force removes (node-crossing frequency v / h = 278 Hz at 250 km/h).",
        "## Mesh (time step fixed at the finest)", table(conv["mesh"], keys),
        "## Time step (mesh fixed at the finest)", table(conv["time_step"], keys),
        "## Cost per step (advance + contact_wire_height, dt = 1 ms)",
        table(results["cost"], ["spans", "element_length_m", "unknowns", "build_s", "us_per_step",
                                "cpu_us_per_step"]),
        "Wall time includes waiting for the CPU when the 2-core machine is shared; CPU time is "
        "the process's own.",
        "## Whole EN 50318 run, catenary alone",
        f"{run['line']}, 600 m at 250 km/h, dt = 1 ms, default element length "
        f"{run['element_length_m']} m: {run['steps']} steps, {run['simulated_s']} s simulated in "
        f"{run['wall_s']} s wall time = {run['us_per_step']} us per step "
        f"({run['cpu_us_per_step']} us CPU): **{run['real_time_factor']} x real time** "
        f"({run['real_time_factor_cpu']} x on CPU time).",
        "## Pre-state and elasticity (central span)"]
    for name, data in pre.items():
        e = data["elasticity"]
        parts.append(
            f"**{name}**: dropper lengths {data['dropper_lengths_m']} m"
            + (f" (published: {data['published_lengths_m']} m)" if data["published_lengths_m"] else "")
            + f"; dropper forces {data['dropper_forces_N']} N; steady-arm preload "
            f"{data['steady_arm_preload_N']} N, messenger-support preload "
            f"{data['messenger_support_preload_N']} N. Elasticity: {e['at_support_mm_per_N']} mm/N "
            f"at the support, {e['at_mid_span_mm_per_N']} mm/N at mid-span, max "
            f"{e['max_mm_per_N']} mm/N at {e['x_of_max_m']} m, min {e['min_mm_per_N']} mm/N at "
            f"{e['x_of_min_m']} m, uniformity (max - min)/(max + min) = {e['uniformity_pct']} %.")
    path.write_text("\n\n".join(parts) + "\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarser sets (a few seconds)")
    args = parser.parse_args(argv)
    say = lambda message: print(message, flush=True)  # noqa: E731
    line = load_line("en50318-2002")
    results = {"machine": f"{platform.platform()}, {os.cpu_count()} cores, Python "
                          f"{platform.python_version()}",
               "default_element_length_m": DEFAULT_ELEMENT_LENGTH,
               "quick": args.quick,
               "convergence": convergence(line, args.quick, say),
               "cost": cost(line, args.quick, say),
               "whole_run": whole_run(line),
               "prestate": prestate()}
    (HERE / "catenary_convergence.json").write_text(json.dumps(results, indent=2) + "\n")
    write_markdown(results, HERE / "catenary_convergence.md")
    say(f"wrote {HERE / 'catenary_convergence.json'} and .md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
