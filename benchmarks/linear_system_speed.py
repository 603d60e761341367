"""Benchmark: ``PhysicalLinear.linear_system`` per call and the data-driven starts on
``physical-linear``, the code of an earlier commit against the working tree, in the same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -P benchmarks/linear_system_speed.py [--repeat 3]

Writes benchmarks/linear_system_speed.json and benchmarks/linear_system_speed.md.

``before``: ``identification/structures/{static_kernel,linearisation,physical}.py`` as of
``--before`` (default: the commit before the linearisation's shortcuts), read with ``git show``
and loaded under their own names next to the current ones (each importing the others' old
versions), the structure the same (its attributes copied). ``after``: the working tree. The
case is the rig story's training run (``docs/diagnosis/rig_story.py``: APRBS, seed 41, 25 s,
bar and hinge friction on) with the diagnosis' ``physical-linear`` structure, as in
``benchmarks/frequency_polish_speed.py``.

Per call: the parameter sets a small mapping (32 screening points, 4 polished starts) passes to
``linear_system``, in its order (the remembered equilibria hit as in a fit), each version's
remembered equilibria cleared first. Then
:func:`~panto.identification.estimation.global_fit.initial_from_data` (256 screening points, 16
polished starts). Runs alternate (before, after, after, before, ...)
so a change in the other work on the machine falls on both; CPU time of this process is the
measure (wall time recorded too), the ratio before / after of the medians reported. Every
matrix and every candidate (parameters, cost, rms) must be bit for bit those of the first run.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import subprocess
import sys
import time
import types
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "docs" / "diagnosis"))
sys.path.insert(0, str(HERE))

from frequency_polish_speed import story_case  # noqa: E402  (the sibling benchmark)

#: The commit before ``linear_system``'s shortcuts (operating point and signals remembered,
#: the balance bound to a parameter set, numpy's solve without its wrapper).
BEFORE = "62fd592"
MODULES = ("static_kernel", "linearisation", "physical")


def load_before(revision: str) -> dict[str, types.ModuleType]:
    """The :data:`MODULES` as of `revision`, in fresh module objects; ``sys.modules`` and the
    package's attributes restored to the current ones afterwards."""
    package = importlib.import_module("panto.identification.structures")
    current = {name: importlib.import_module(f"{package.__name__}.{name}") for name in MODULES}
    old = {}
    try:
        for name in MODULES:
            full, path = f"{package.__name__}.{name}", f"identification/structures/{name}.py"
            source = subprocess.run(["git", "show", f"{revision}:{path}"], cwd=ROOT, check=True,
                                    capture_output=True, text=True).stdout
            module = types.ModuleType(full)
            module.__file__ = str(ROOT / path)  # the static functions' cache key: the same
            sys.modules[full] = module
            setattr(package, name, module)
            exec(compile(source, f"{revision}:{path}", "exec"), module.__dict__)
            old[name] = module
    finally:
        for name, module in current.items():
            sys.modules[f"{package.__name__}.{name}"] = module
            setattr(package, name, module)
    return old


def recorded_calls(structure, data, free) -> list[dict[str, float]]:
    """The parameter sets a small mapping passes to ``linear_system``, in order."""
    from panto.identification.estimation import global_fit

    calls = []
    own = type(structure).linear_system

    def recording(self, parameters, data):
        calls.append(dict(parameters))
        return own(self, parameters, data)

    type(structure).linear_system = recording
    try:
        global_fit.initial_from_data(structure, data, free,
                                     options=global_fit.FrequencyFitOptions(screening=32, starts=4))
    finally:
        type(structure).linear_system = own
    return calls


def per_call(structure, linearisation, data, calls) -> tuple[float, float, list]:
    """Wall and CPU time per ``linear_system`` call over `calls` and the outcomes."""
    linearisation._EQUILIBRIA.clear()
    wall, cpu = time.perf_counter(), time.process_time()
    outcomes = []
    for parameters in calls:
        try:
            outcomes.append(structure.linear_system(parameters, data))
        except ValueError as error:
            outcomes.append(str(error))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall / len(calls), cpu / len(calls), outcomes


def mapping(structure, linearisation, data, free) -> tuple[float, float, list]:
    """Wall and CPU time of one ``initial_from_data`` and its candidates as plain lists."""
    from panto.identification.estimation.global_fit import initial_from_data

    linearisation._EQUILIBRIA.clear()
    wall, cpu = time.perf_counter(), time.process_time()
    candidates = initial_from_data(structure, data, free)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall, cpu, [(list(c.parameters), list(c.parameters.values()), c.cost, c.rms)
                       for c in candidates]


def same_outcomes(first: list, second: list) -> bool:
    """Bit for bit the same matrices, the same refusals."""
    return len(first) == len(second) and all(
        a == b if isinstance(a, str) or isinstance(b, str)
        else all(np.array_equal(x, y) for x, y in zip(a, b)) for a, b in zip(first, second))


def same_candidates(first: list, second: list) -> bool:
    """Bit for bit the same candidates (names, parameter values, cost, rms)."""
    return len(first) == len(second) and all(
        a[0] == b[0] and np.array_equal(a[1], b[1]) and a[2] == b[2] and a[3] == b[3]
        for a, b in zip(first, second))


def alternate(repeat: int, measure, same) -> dict:
    """`repeat` pairs of ``measure(version)`` alternating; medians, ratios, identity."""
    runs, reference, identical = {"before": [], "after": []}, None, True
    for k in range(repeat):
        for version in (("before", "after") if k % 2 == 0 else ("after", "before")):
            wall, cpu, outcome = measure(version)
            reference = outcome if reference is None else reference
            identical &= same(reference, outcome)
            runs[version].append({"wall_s": wall, "cpu_s": cpu})
            print(f"{version}: {wall:.6g} s wall, {cpu:.6g} s CPU, identical {identical}",
                  flush=True)
    medians = {version: {key: float(np.median([r[key] for r in runs[version]]))
                         for key in ("wall_s", "cpu_s")} for version in runs}
    return {"runs": runs, "medians": medians,
            "ratio_wall": medians["before"]["wall_s"] / medians["after"]["wall_s"],
            "ratio_cpu": medians["before"]["cpu_s"] / medians["after"]["cpu_s"],
            "identical": bool(identical)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="pairs of runs of each measure")
    parser.add_argument("--before", default=BEFORE, help="the commit to compare with")
    args = parser.parse_args()
    from panto.identification.estimation.global_fit import FrequencyFitOptions, initial_from_data
    from panto.identification.structures import linearisation

    old = load_before(args.before)
    structure, data, free = story_case()
    previous = object.__new__(old["physical"].PhysicalLinear)
    previous.__dict__.update(structure.__dict__)
    versions = {"before": (previous, old["linearisation"]), "after": (structure, linearisation)}
    for version in versions.values():  # loads the modules and the nominal starts, untimed
        initial_from_data(version[0], data, free,
                          options=FrequencyFitOptions(screening=8, starts=1))
    calls = recorded_calls(structure, data, free)
    print(f"{len(calls)} linear_system calls", flush=True)
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, "
                          f"Python {platform.python_version()}, NumPy {np.__version__}",
               "command": "OPENBLAS_NUM_THREADS=1 .venv/bin/python -P "
                          f"benchmarks/linear_system_speed.py --repeat {args.repeat}",
               "before": args.before, "calls": len(calls),
               "linear_system": alternate(args.repeat, lambda v: per_call(
                   versions[v][0], versions[v][1], data, calls), same_outcomes),
               "initial_from_data": alternate(args.repeat, lambda v: mapping(
                   versions[v][0], versions[v][1], data, free), same_candidates)}
    (HERE / "linear_system_speed.json").write_text(json.dumps(results, indent=2))
    lines = ["# `PhysicalLinear.linear_system`: before and after its shortcuts", "",
             f"Date: {results['date']}. Machine: {results['machine']}, shared with other work.",
             "", f"Command: `{results['command']}`", "",
             f"Before: the modules as of commit `{args.before}`; after: the working tree; "
             "alternating in one process, medians of "
             f"{args.repeat} runs each. The rig story's training run, `physical-linear`. Per "
             f"call: the {len(calls)} parameter sets of a small mapping in order; the mapping: "
             "`initial_from_data` (256 screening points, 16 polished starts). 'identical': "
             "every matrix and refusal, every candidate (parameters, cost, rms) bit for bit "
             "those of the first run.", "",
             "| measure | CPU before | CPU after | CPU ratio | wall before | wall after | "
             "wall ratio | identical |", "|---|---|---|---|---|---|---|---|"]
    for name, unit, scale in (("linear_system", "us", 1e6), ("initial_from_data", "s", 1.0)):
        case, m = results[name], results[name]["medians"]
        lines.append(f"| {name} [{unit}] | {m['before']['cpu_s'] * scale:.4g} | "
                     f"{m['after']['cpu_s'] * scale:.4g} | {case['ratio_cpu']:.2f} | "
                     f"{m['before']['wall_s'] * scale:.4g} | {m['after']['wall_s'] * scale:.4g} | "
                     f"{case['ratio_wall']:.2f} | {'yes' if case['identical'] else 'NO'} |")
    (HERE / "linear_system_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
