"""Benchmark: the data-driven starts' polish with its finite-difference columns evaluated one by
one and together, in the same run.

    .venv/bin/python -P benchmarks/frequency_polish_speed.py [--repeat 2]

Writes benchmarks/frequency_polish_speed.json and benchmarks/frequency_polish_speed.md.

:func:`panto.identification.estimation.global_fit.initial_from_data` (256 screening points, 16
polished starts) on three cases: the rig story's training run (``docs/diagnosis/rig_story.py``:
APRBS, seed 41, 25 s, bar and hinge friction on) with the ``physical-linear`` structure of the
diagnosis, and the three- and two-mass oscillators on the three-mass plant of
``tests/test_global_fit.py`` (as there and in ``tests/test_adequacy.py``). ``plain``: one cost
call per Jacobian column (``BATCHED_COLUMNS = False``, as before); ``batched``: the columns
through ``least_squares``' ``workers``, their frequency responses stacked
(:meth:`~panto.identification.estimation.global_fit._ReducedCost.columns`). Polishing is almost
all of the time (the screening is 257 cost calls against some 10 000-30 000).

A small untimed mapping first loads the modules. The cases alternate (plain, batched, batched,
plain, ...) so a change in the other work on the machine falls on both; wall and CPU time of
this process are recorded and the ratio plain / batched of the medians reported. Every run's
candidates (parameters, cost, rms) must be bit for bit those of the first plain run.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "docs" / "diagnosis"))


def story_case():
    """The rig story's training run and the diagnosis' ``physical-linear`` structure."""
    from rig_story import record

    from panto.identification.diagnosis.support import build_structure

    with tempfile.TemporaryDirectory() as tmp:
        data = record(Path(tmp) / "t", "aprbs_training", 41, 25.0, effects=True)
    structure, free = build_structure("physical-linear", data, {})
    return structure, data, free


def oscillator_case(masses: int, seed: int, duration: float):
    """An oscillator structure on the three-mass plant of ``tests/test_global_fit.py``."""
    from test_global_fit import _inputs, _three_mass

    from panto.identification.estimation.base import IdentificationData
    from panto.identification.structures.oscillators import OscillatorStructure

    rng = np.random.default_rng(seed)
    t, eta, p = _inputs(duration, rng)
    force = _three_mass(t, eta, p)
    measured = force + 0.03 * force.std() * rng.normal(size=len(t))
    data = IdentificationData(t, np.column_stack([eta, p]), measured[:, None], ("eta", "p"),
                              ("F_c",), {"eta": "m", "p": "bar", "F_c": "N"})
    structure = OscillatorStructure(masses, outputs=("F_c",))
    return structure, data, structure.default_free()


CASES = {"physical-linear (rig story training run)": story_case,
         "three-mass oscillator (tests/test_global_fit.py, seed 0, 30 s)":
             lambda: oscillator_case(3, 0, 30.0),
         "two-mass oscillator (tests/test_adequacy.py, seed 1, 12 s)":
             lambda: oscillator_case(2, 1, 12.0)}


def run(structure, data, free, batched: bool) -> tuple[float, float, list]:
    """Wall and CPU time of one mapping and its candidates as plain lists."""
    from panto.identification.estimation import global_fit
    from panto.identification.structures import linearisation

    global_fit.BATCHED_COLUMNS = batched
    linearisation._EQUILIBRIA.clear()  # no equilibria remembered from the previous run
    wall, cpu = time.perf_counter(), time.process_time()
    candidates = global_fit.initial_from_data(structure, data, free)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall, cpu, [(list(c.parameters), list(c.parameters.values()), c.cost, c.rms)
                       for c in candidates]


def identical(first: list, second: list) -> bool:
    """Bit for bit the same candidates (names, parameter values, cost, rms)."""
    return len(first) == len(second) and all(
        a[0] == b[0] and np.array_equal(a[1], b[1]) and a[2] == b[2] and a[3] == b[3]
        for a, b in zip(first, second))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2, help="pairs of runs per case")
    args = parser.parse_args()
    from scipy import __version__ as scipy_version

    from panto.identification.estimation import global_fit
    from panto.identification.estimation.global_fit import FrequencyFitOptions

    if not global_fit.BATCHED_COLUMNS:
        sys.exit(f"SciPy {scipy_version} has no least_squares(workers=...): nothing to compare")
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, "
                          f"Python {platform.python_version()}, SciPy {scipy_version}, "
                          f"NumPy {np.__version__}",
               "command": "OPENBLAS_NUM_THREADS=1 .venv/bin/python -P "
                          f"benchmarks/frequency_polish_speed.py --repeat {args.repeat}",
               "cases": {}}
    for name, make in CASES.items():
        structure, data, free = make()
        global_fit.initial_from_data(structure, data, free,  # loads the modules, untimed
                                     options=FrequencyFitOptions(screening=8, starts=1))
        runs = {"plain": [], "batched": []}
        reference, same = None, True
        for k in range(args.repeat):
            for mode in (("plain", "batched") if k % 2 == 0 else ("batched", "plain")):
                wall, cpu, candidates = run(structure, data, free, mode == "batched")
                reference = reference if reference is not None else candidates
                same &= identical(reference, candidates)
                runs[mode].append({"wall_s": wall, "cpu_s": cpu})
                print(f"{name}: {mode} {wall:.2f} s wall, {cpu:.2f} s CPU, identical {same}",
                      flush=True)
        medians = {mode: {key: float(np.median([r[key] for r in runs[mode]]))
                          for key in ("wall_s", "cpu_s")} for mode in runs}
        results["cases"][name] = {
            "runs": runs, "medians": medians,
            "ratio_wall": medians["plain"]["wall_s"] / medians["batched"]["wall_s"],
            "ratio_cpu": medians["plain"]["cpu_s"] / medians["batched"]["cpu_s"],
            "identical": bool(same),
            "candidate_costs": [c[2] for c in reference]}
    global_fit.BATCHED_COLUMNS = True
    (HERE / "frequency_polish_speed.json").write_text(json.dumps(results, indent=2))
    lines = ["# Data-driven starts: finite-difference columns one by one and together", "",
             f"Date: {results['date']}. Machine: {results['machine']}, shared with other work.",
             "", f"Command: `{results['command']}`", "",
             "`initial_from_data` (256 screening points, 16 polished starts), plain (one cost "
             "call per Jacobian column) and batched (the columns through `least_squares`' "
             "`workers`, their frequency responses stacked) alternating in one process; "
             f"medians of {args.repeat} runs each. 'identical': every run's candidates "
             "(parameters, cost, rms) bit for bit those of the first plain run.", "",
             "| case | wall plain [s] | wall batched [s] | wall ratio | CPU plain [s] | "
             "CPU batched [s] | CPU ratio | identical |", "|---|---|---|---|---|---|---|---|"]
    for name, case in results["cases"].items():
        m = case["medians"]
        lines.append(f"| {name} | {m['plain']['wall_s']:.2f} | {m['batched']['wall_s']:.2f} | "
                     f"{case['ratio_wall']:.2f} | {m['plain']['cpu_s']:.2f} | "
                     f"{m['batched']['cpu_s']:.2f} | {case['ratio_cpu']:.2f} | "
                     f"{'yes' if case['identical'] else 'NO'} |")
    (HERE / "frequency_polish_speed.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
