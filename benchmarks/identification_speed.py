"""Benchmark: identify the physical model (13 parameters of Table 4.1) - LM against a thesis-style GA.

Run by hand; writes benchmarks/identification_speed.json and benchmarks/identification_speed.md.

    .venv/bin/python benchmarks/identification_speed.py [--training RUN] [--quick]
        [--population 200] [--generations 60] [--workers 2]
        [--nonlinear-only [--skip-reference]] [--friction-only]

Data: 60 s of the virtual test bed's training run (APRBS on both inputs, imperfections on) at
50 Hz (issue 6, "Benchmark"). Both runs fit the linearised physical model ("physical-linear":
equilibrium and exact linearisation recomputed for every candidate, as the thesis did, section
4.1.3) to the force and the cross-bar position from Table 4.1 as the start / prior:

1. Levenberg-Marquardt (panto.identification.estimation.least_squares.fit_least_squares): wall time and fit.
2. The thesis' way: NSGA-II (panto.identification.estimation.genetic.fit_pareto) with a large population, every
   generation evaluated on a process pool, stopped as soon as one candidate reaches the LM run's
   least-squares cost sum_j (1 - fit_j / 100)^2 (the "same fit"), or at the generation limit.

3. With the FMU in the loop (``PhysicalNonlinear``): LM, the Jacobian's columns on the process pool,
   each finite-difference Jacobian reused with Broyden updates (the structure's
   ``broyden_updates``), beside the reference with a fresh Jacobian every iteration
   (``broyden=0``, the method before). ``--nonlinear-only`` measures these two rows alone and
   keeps the other rows of the last report.
4. The friction oscillators (two- and three-mass, Coulomb friction: ``identify_oscillator``, one
   process, as ``panto identify --model two-mass-friction``) on the whole training run (the
   record of the README's comparison table), and the cost of one free run of each with the
   compiled stick-slip kernel against the Python reference loop (``PANTO_FRICTION_KERNEL=0``),
   both measured here, in CPU seconds.

The machine load is recorded: other processes on the same cores slow everything down (wall
times); CPU times are given beside them.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

#: The demo's training run if `panto demo --out out` has been run, else one recorded here.
DEFAULT_RUN = HERE.parent / "out" / "runs" / "training_0001"


def _training_run(requested: str | None, seconds: float) -> Path:
    """The run to identify from: the one given, the demo's, or a fresh virtual APRBS run."""
    if requested:
        return Path(requested)
    if DEFAULT_RUN.is_dir():
        return DEFAULT_RUN
    import tempfile
    from dataclasses import replace

    from panto.build_fmu.project import project_fmu
    from panto.rig.profiles import load_profile
    from panto.rig.virtual import run_virtual_profile

    folder = Path(tempfile.mkdtemp(prefix="panto-bench-")) / "training"
    print(f"recording a {seconds:g} s virtual APRBS training run into {folder} ...", flush=True)
    profile = replace(load_profile("aprbs_training"), duration=seconds + 1.0)
    run_virtual_profile(profile, fmu_path=project_fmu("Pantograph"), folder=folder, seed=1)
    return folder


def _data(run: Path, seconds: float):
    from panto.identification.data.datasets import pantograph_data

    data = pantograph_data(run, rate=50.0)
    start = float(data.time[0])
    return data.segment(start, start + seconds)


def _lm(structure, data, free, executor=None, **options) -> dict:
    from panto.identification.estimation.genetic import polish_cost
    from panto.identification.estimation.least_squares import fit_least_squares

    started, cpu = time.perf_counter(), time.process_time()
    result = fit_least_squares(structure, data, free=free, executor=executor, **options)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    fits = {o: float(result.fit[o]) for o in ("y_cb", "F_c")}
    return {"wall_time_s": wall, "cpu_main_s": cpu, "fit_percent": fits,
            "cost": polish_cost(list(fits.values())), "evaluations": result.n_evaluations,
            "iterations": result.details.get("iterations"), "success": result.success,
            "message": result.message, "parameters": {n: result.parameters[n] for n in free}}


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _nonlinear(data, free, workers: int, reference: bool) -> dict:
    """The FMU-in-the-loop LM (Broyden updates, the structure's default) and, with `reference`,
    the same fit with a fresh Jacobian every iteration; each on its own pool of `workers`, CPU
    of the main process and of the (reaped) workers, the load before each."""
    from panto.identification.structures.physical import PhysicalNonlinear

    structure = PhysicalNonlinear(outputs=("y_cb", "F_c"))
    started = time.process_time()
    for _ in range(3):
        structure.simulate(structure.nominal(), data)
    one_run = (time.process_time() - started) / 3
    rows = {}
    for label, options in [("broyden", {})] + ([("reference", {"broyden": 0})] if reference
                                               else []):
        print(f"LM with the FMU in the loop (nonlinear model, {label}) ...", flush=True)
        load, children = os.getloadavg()[0], _children_cpu()
        with ProcessPoolExecutor(workers) as pool:
            row = _lm(structure, data, free, pool, **options)
        row.update(cpu_workers_s=_children_cpu() - children, load_before=round(load, 2),
                   load_after=round(os.getloadavg()[0], 2), one_run_cpu_s=one_run,
                   broyden=options.get("broyden", structure.broyden_updates))
        print(f"  {label}: {row['wall_time_s']:.1f} s wall, "
              f"{row['cpu_main_s'] + row['cpu_workers_s']:.1f} s CPU, {row['evaluations']} "
              f"evaluations, fit {row['fit_percent']}", flush=True)
        rows[label] = row
    return rows["broyden"] | ({"reference": rows["reference"]} if reference else {})


def _nonlinear_only(run: Path, args) -> None:
    """Rerun the nonlinear rows into the last report (its other rows kept as measured)."""
    from panto.identification.structures.physical import TABLE_4_1

    path = HERE / "identification_speed.json"
    report = json.loads(path.read_text())
    previous = report.get("nonlinear_lm") or {}
    report["nonlinear_lm"] = _nonlinear(_data(run, args.seconds), TABLE_4_1, args.workers,
                                        not args.skip_reference)
    if args.skip_reference and "reference" in previous:  # kept as measured (its own load)
        report["nonlinear_lm"]["reference"] = previous["reference"]
    report["nonlinear_lm"]["command"] = ("python benchmarks/identification_speed.py "
                                         + " ".join(sys.argv[1:]))
    path.write_text(json.dumps(report, indent=2) + "\n")
    (HERE / "identification_speed.md").write_text(_markdown(report))
    print(_markdown(report))


def _ga(structure, data, free, target: float, population: int, generations: int,
        workers: int) -> dict:
    from panto.identification.estimation.genetic import fit_pareto, polish_cost

    lines = []

    def say(line: str) -> None:
        lines.append(line)
        print("  GA " + line, flush=True)

    started = time.perf_counter()
    with ProcessPoolExecutor(workers) as pool:
        pareto = fit_pareto(structure, data, free=free, population=population,
                            generations=generations, executor=pool, seed=1, progress=say,
                            stop=lambda record: record["best_cost"] <= target)
    wall = time.perf_counter() - started
    last = pareto.history[-1]
    best = min(range(len(pareto.front)), key=lambda i: polish_cost(pareto.objectives[i]),
               default=None)
    return {"wall_time_s": wall, "population": population, "generations_run": len(pareto.history),
            "generation_limit": generations, "evaluations": pareto.n_evaluations,
            "reached_lm_fit": last["best_cost"] <= target, "best_cost": last["best_cost"],
            "best_fit_percent": None if best is None else
            dict(zip(pareto.objective_names, pareto.objectives[best].tolist())),
            "front_size": len(pareto.front),
            "history": [{k: h[k] for k in ("generation", "evaluations", "best_fit", "best_cost",
                                           "seconds")} for h in pareto.history]}


def _friction(run: Path, reference_runs: int = 2, compiled_runs: int = 10) -> list[dict]:
    """Fit both friction oscillators on the whole run; time one free run per kernel path."""
    from panto.identification.data.datasets import pantograph_data
    from panto.identification.structures import friction_kernel
    from panto.identification.structures.oscillators import OscillatorStructure, identify_oscillator

    data = pantograph_data(run, rate=50.0)
    rows = []
    for masses in (2, 3):
        structure = OscillatorStructure(masses, True, outputs=("F_c", "y_cb"))
        per_run = {}
        for switch, count in (("0", reference_runs), ("1", compiled_runs)):
            os.environ[friction_kernel.SWITCH_VARIABLE] = switch
            started = time.process_time()
            for _ in range(count):
                structure.simulate(structure.nominal(), data)
            per_run[switch] = (time.process_time() - started) / count
        os.environ[friction_kernel.SWITCH_VARIABLE] = "1"
        wall, cpu = time.perf_counter(), time.process_time()
        result = identify_oscillator(data, masses=masses, friction=True)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        fits = {o: float(result.fit[o]) for o in ("y_cb", "F_c")}
        rows.append({"structure": structure.name, "samples": len(data), "wall_time_s": wall,
                     "cpu_time_s": cpu, "evaluations": result.n_evaluations,
                     "fit_percent": fits, "message": result.message,
                     "compiled": friction_kernel.available(),
                     "run_cpu_s": {"python": per_run["0"], "compiled": per_run["1"]}})
        print(f"  {structure.name}: {wall:.1f} s wall, {cpu:.1f} s CPU, "
              f"{result.n_evaluations} evaluations, fit {fits}; one run {per_run['0']:.3f} s "
              f"(Python) / {per_run['1']:.4f} s (compiled) CPU", flush=True)
    return rows


#: The figures before issue 23 (the Python stick-slip loop), for the before/after comparison.
BEFORE_ISSUE_23 = (
    "Before the compiled stick-slip kernel (issue 23): two-mass-friction 70.9 s and "
    "three-mass-friction 275.3 s to fit on the demo's 180 s training run (README comparison "
    "table, `panto compare ... --workers 2`, Python loop). On this run, two-mass-friction with "
    "`PANTO_FRICTION_KERNEL=0` (the Python loop): 136.6 s of CPU (640.9 s wall at load 10.5), "
    "the same 133 evaluations, fits and parameters equal to the compiled fit's within 2e-6 "
    "(relative). The nonlinear LM row before: 167.1 s, 1598 "
    "evaluations, fit 60.3 / 80.1 %, LS cost 0.1972 (this benchmark, the demo's run, load 1.86). "
    "The nonlinear rows: the FMU gives no parameter sensitivities (its directional "
    "derivatives are d(der, y)/d(x, u) only), so the Jacobian is by finite differences, its "
    "columns on the process pool (one pool for the whole fit, one FMU instance per worker, "
    "reset for every run); one run costs about 0.09 s of CPU, nearly all of it the FMU's own "
    "integrator (Model Exchange through fmpy's CVODE: 0.67 s per run at tolerance 1e-6, 0.21 s "
    "at 1e-4). What shortened the fit is fewer runs: Broyden rank-1 updates of the Jacobian "
    "between fresh ones, and the damping trials of a step evaluated in pairs on the pool. "
    "Starting it from the linearised fit's optimum (k and c2 at their upper bounds there) did "
    "not shorten it (not converged after 669 evaluations, cost still above the nominal "
    "start's).")


def _nonlinear_lines(row: dict, workers: int) -> list[str]:
    """The FMU-in-the-loop rows: the Broyden fit and (if measured) its reference."""
    rows = [(row, f"Broyden updates, a fresh Jacobian after at most {row.get('broyden', '?')}")]
    if "reference" in row:
        rows.append((row["reference"], "a fresh Jacobian every iteration (the method before)"))
    lines = []
    for entry, how in rows:
        cpu = ("" if "cpu_workers_s" not in entry else
               f"{entry['cpu_main_s'] + entry['cpu_workers_s']:.1f} s CPU, load "
               f"{entry['load_before']} before, {entry['load_after']} after; ")
        lines.append(
            f"| Levenberg-Marquardt, nonlinear model (FMU in the loop), Jacobian on {workers} "
            f"processes, {how} | {entry['wall_time_s']:.1f} | {entry['evaluations']} | "
            f"{entry['fit_percent']['F_c']:.1f} | {entry['fit_percent']['y_cb']:.1f} | "
            f"{entry['cost']:.4f} | {cpu}{entry['message'][:60]} |")
    return lines


def _friction_lines(rows: list[dict]) -> list[str]:
    rerun = (f" Measured separately: `{rows[0]['command']}`, load {rows[0]['load_before']} "
             f"before, {rows[0]['load_after']} after." if "command" in rows[0] else "")
    lines = ["", f"Friction oscillators on the whole run ({rows[0]['samples']} samples at 50 Hz), "
             "one process, compiled stick-slip kernel; one free run timed with the Python "
             "reference loop and with the kernel (CPU)." + rerun, "",
             "| structure | wall time [s] | CPU [s] | evaluations | fit F_c [%] | fit y_cb [%] | "
             "one run, Python [s] | one run, compiled [s] | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        python, compiled = row["run_cpu_s"]["python"], row["run_cpu_s"]["compiled"]
        lines.append(f"| {row['structure']} | {row['wall_time_s']:.1f} | {row['cpu_time_s']:.1f} "
                     f"| {row['evaluations']} | {row['fit_percent']['F_c']:.1f} | "
                     f"{row['fit_percent']['y_cb']:.1f} | {python:.3f} | {compiled:.4f} | "
                     f"{python / compiled:.0f}x |")
    return lines + ["", BEFORE_ISSUE_23]


def _friction_only(run: Path) -> None:
    """Rerun the friction rows into the last report (its other rows kept as measured)."""
    path = HERE / "identification_speed.json"
    report = json.loads(path.read_text())
    load = os.getloadavg()[0]
    rows = _friction(run)
    command = "python benchmarks/identification_speed.py " + " ".join(sys.argv[1:])
    for row in rows:
        row.update(command=command, load_before=round(load, 2),
                   load_after=round(os.getloadavg()[0], 2))
    report["friction"] = rows
    path.write_text(json.dumps(report, indent=2) + "\n")
    (HERE / "identification_speed.md").write_text(_markdown(report))
    print(_markdown(report))


def _markdown(report: dict) -> str:
    lm, ga = report["lm"], report["ga"]
    ga_fit = ga["best_fit_percent"] or {}
    lines = [
        "# Identification speed: physical model (13 parameters), LM vs thesis-style GA", "",
        f"Data: {report['data']['source']}, {report['data']['seconds']:.0f} s at 50 Hz "
        f"({report['data']['samples']} samples). Machine: {report['machine']['cpus']} CPUs, "
        f"load {report['machine']['load_before']} before the run, "
        f"{report['machine'].get('load_after', 'n/a')} after it. Command: "
        f"`{report['command']}`.", "",
        "| method | wall time [s] | evaluations | fit F_c [%] | fit y_cb [%] | LS cost | note |",
        "|---|---|---|---|---|---|---|",
        f"| Levenberg-Marquardt | {lm['wall_time_s']:.1f} | {lm['evaluations']} | "
        f"{lm['fit_percent']['F_c']:.1f} | {lm['fit_percent']['y_cb']:.1f} | {lm['cost']:.4f} | "
        f"{lm['message'][:60]} |",
        f"| NSGA-II, population {ga['population']}, {report['workers']} processes | "
        f"{ga['wall_time_s']:.1f} | {ga['evaluations']} | {ga_fit.get('F_c', float('nan')):.1f} "
        f"| {ga_fit.get('y_cb', float('nan')):.1f} | {ga['best_cost']:.4f} | "
        + ("reached the LM fit" if ga["reached_lm_fit"] else
           f"did NOT reach the LM fit in {ga['generations_run']} generations") + " |",
    ]
    nonlinear = report.get("nonlinear_lm")
    if nonlinear:
        lines += _nonlinear_lines(nonlinear, report["workers"])
        if "one_run_cpu_s" in nonlinear:
            lines += ["", "Nonlinear rows" + (f" measured separately: `{nonlinear['command']}`"
                                              if "command" in nonlinear else "")
                      + f"; one run of the FMU {nonlinear['one_run_cpu_s']:.3f} s of CPU. "
                      "CPU = main process + pool workers."]
    if report.get("friction"):
        lines += _friction_lines(report["friction"])
    lines += [
        "",
        "The GA's fits are those of its front's best least-squares solution; the LS cost is "
        "sum_j (1 - fit_j/100)^2 (the GA stops when one candidate reaches the LM cost). The thesis "
        "took several hours for its GA (population 1000) on an office PC (section 4.8).",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--training", help="training run folder (default: the demo's "
                        "out/runs/training_0001, else a fresh virtual run)")
    parser.add_argument("--skip-nonlinear", action="store_true",
                        help="skip the FMU-in-the-loop identification (minutes)")
    parser.add_argument("--skip-friction", action="store_true",
                        help="skip the friction oscillators' fits")
    parser.add_argument("--friction-only", action="store_true",
                        help="run only the friction rows, keep the other rows of the last "
                        "identification_speed.json")
    parser.add_argument("--nonlinear-only", action="store_true",
                        help="run only the nonlinear (FMU in the loop) rows, keep the other rows "
                        "of the last identification_speed.json")
    parser.add_argument("--skip-reference", action="store_true",
                        help="nonlinear rows: skip the reference fit with a fresh Jacobian every "
                        "iteration (minutes)")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--population", type=int, default=200)
    parser.add_argument("--generations", type=int, default=60)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="population 40, 5 generations")
    args = parser.parse_args()
    if args.quick:
        args.population, args.generations = 40, 5
    from panto.identification.structures.physical import TABLE_4_1, PhysicalLinear

    run = _training_run(args.training, args.seconds)
    if args.friction_only:
        _friction_only(run)
        return
    if args.nonlinear_only:
        _nonlinear_only(run, args)
        return
    data = _data(run, args.seconds)
    structure = PhysicalLinear(outputs=("y_cb", "F_c"))
    load = os.getloadavg()[0]
    print(f"LM on {len(data)} samples ...", flush=True)
    lm = _lm(structure, data, TABLE_4_1)
    print(f"  LM {lm['wall_time_s']:.1f} s, fit {lm['fit_percent']}", flush=True)
    ga = _ga(structure, data, TABLE_4_1, lm["cost"], args.population, args.generations,
             args.workers)
    nonlinear = None
    if not args.skip_nonlinear:
        nonlinear = _nonlinear(data, TABLE_4_1, args.workers, not args.skip_reference)
    friction = None
    if not args.skip_friction:
        print("friction oscillators on the whole run ...", flush=True)
        friction = _friction(run)
    load_after = os.getloadavg()[0]
    report = {"command": "python benchmarks/identification_speed.py " + " ".join(sys.argv[1:]),
              "data": {"source": str(run), "seconds": args.seconds,
                       "samples": len(data)},
              "machine": {"cpus": os.cpu_count(), "load_before": round(load, 2),
                          "load_after": round(load_after, 2),
                          "python": platform.python_version()},
              "workers": args.workers, "lm": lm, "ga": ga, "nonlinear_lm": nonlinear,
              "friction": friction}
    (HERE / "identification_speed.json").write_text(json.dumps(report, indent=2) + "\n")
    (HERE / "identification_speed.md").write_text(_markdown(report))
    print(_markdown(report))


if __name__ == "__main__":
    main()
