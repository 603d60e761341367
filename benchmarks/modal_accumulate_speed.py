"""Benchmark: ``physical-linear``'s free run with each mode's share added to the states by the
compiled loop (``static_kernel.accumulate_mode``) against NumPy's outer products, in the same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -P benchmarks/modal_accumulate_speed.py [--repeat 5]

Writes benchmarks/modal_accumulate_speed.json and benchmarks/modal_accumulate_speed.md.

The case is the rig story's training run with the diagnosis' ``physical-linear`` structure
(``frequency_polish_speed.story_case``), simulated at 40 parameter sets (the nominal scaled by
0.9-1.1 per parameter, fixed seed), once each per measurement. ``numpy``: the accumulation
switched off (``accumulate_mode`` returning False: NumPy's ``states += w (outer - outer)``);
``compiled``: as shipped. Runs alternate (numpy, compiled, compiled, numpy, ...) so a change in
the other work on the machine falls on both; CPU time of this process is the measure, the ratio
of the medians reported. Every simulated output must be bit for bit the first run's.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from frequency_polish_speed import story_case  # noqa: E402  (the sibling benchmark)
from linear_system_speed import alternate  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="pairs of runs")
    args = parser.parse_args()
    from panto.identification.structures import static_kernel

    structure, data, free = story_case()
    nominal = structure.nominal()
    rng = np.random.default_rng(7)
    sets = [{k: (v * rng.uniform(0.9, 1.1) if k in free else v) for k, v in nominal.items()}
            for _ in range(40)]
    compiled = static_kernel.accumulate_mode
    if not compiled(np.zeros((1, 1)), np.zeros(1, complex), np.zeros(1, complex), 1.0):
        raise SystemExit("modal_accumulate_speed: no compiled kernel here (no C compiler, or "
                         "PANTO_STATIC_KERNEL=0): nothing to compare")

    def measure(version: str) -> tuple[float, float, list]:
        static_kernel.accumulate_mode = compiled if version == "after" else \
            (lambda *args: False)
        wall, cpu = time.perf_counter(), time.process_time()
        outputs = []
        for values in sets:
            try:
                outputs.append(structure.simulate(values, data))
            except Exception as error:  # an unstable set is refused the same way by both
                outputs.append(type(error).__name__)
        static_kernel.accumulate_mode = compiled
        return time.perf_counter() - wall, time.process_time() - cpu, outputs

    def same(first: list, second: list) -> bool:
        return all((isinstance(a, str) and a == b) or
                   (not isinstance(a, str) and not isinstance(b, str) and np.array_equal(a, b))
                   for a, b in zip(first, second))

    measure("after")  # loads the kernel and warms the caches, untimed
    case = alternate(args.repeat, measure, same)
    results = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
               "machine": f"{platform.platform()}, {os.cpu_count()} CPUs, "
                          f"Python {platform.python_version()}, NumPy {np.__version__}",
               "command": "OPENBLAS_NUM_THREADS=1 .venv/bin/python -P "
                          f"benchmarks/modal_accumulate_speed.py --repeat {args.repeat}",
               "samples": len(data), "simulations": len(sets), **case}
    (HERE / "modal_accumulate_speed.json").write_text(json.dumps(results, indent=2))
    m = case["medians"]
    lines = ["# `physical-linear`'s free run: the modes' shares added by a compiled loop", "",
             f"Date: {results['date']}. Machine: {results['machine']}, shared with other work.",
             "", f"Command: `{results['command']}`", "",
             f"The rig story's training run ({len(data)} samples), {len(sets)} simulations per "
             f"measurement; medians of {args.repeat} alternating runs each. 'numpy': NumPy's "
             "outer products (the accumulation switched off); 'compiled': as shipped. "
             "'identical': every output bit for bit the first run's.", "",
             "| measure | CPU numpy | CPU compiled | CPU ratio | wall numpy | wall compiled | "
             "wall ratio | identical |", "|---|---|---|---|---|---|---|---|",
             f"| one simulation [ms] | {m['before']['cpu_s'] / len(sets) * 1e3:.3g} | "
             f"{m['after']['cpu_s'] / len(sets) * 1e3:.3g} | {case['ratio_cpu']:.2f} | "
             f"{m['before']['wall_s'] / len(sets) * 1e3:.3g} | "
             f"{m['after']['wall_s'] / len(sets) * 1e3:.3g} | {case['ratio_wall']:.2f} | "
             f"{'yes' if case['identical'] else 'NO'} |"]
    (HERE / "modal_accumulate_speed.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
