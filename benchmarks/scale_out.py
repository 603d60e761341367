"""Benchmark: speed-up per worker process of the three parallel paths (issue 23, "Scale-out").

Run by hand; writes ``benchmarks/scale_out.json`` and ``.md``::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/scale_out.py [--workers 1 2 4]

The same executor path for each (a :class:`concurrent.futures.ProcessPoolExecutor` of ``N``
processes; a ``dask.distributed.Client`` is accepted in its place by every one of them, so a
user with a cluster passes the client instead):

- *diagnosis benchmark*: :func:`~panto.identification.diagnosis.benchmark.run_diagnosis_benchmark`
  on 4 virtual-test-bed cases of 10 s, one case per task (its refits in-process);
- *identification multistarts*: :func:`~panto.identification.estimation.least_squares.fit_least_squares`
  of the three-mass oscillator with 12 multistart runs, each run a task;
- *structure comparison*: :func:`~panto.identification.estimation.comparison.compare_structures` of
  physical-linear, three-mass-friction and three-mass, their Jacobian columns as tasks.

Each path is timed once per worker count on the same inputs (wall seconds, the speed-up against one
worker). On a machine with ``c`` cores the speed-up cannot pass ``c``; more workers than cores only
add start-up and contention (that row shows what a user sees when over-subscribing).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import effect_plants  # noqa: E402  (the sibling benchmark module)


def _data():
    """A two-input, two-output three-mass run pair (training, validation) of the families."""
    import diagnosis_families as families

    spec = next(s for s in families.case_sequence("tune", quick=True) if s.label == "clean"
                and s.family == "three-mass")
    case = effect_plants.effect_case(spec)
    return families.to_data(case, 0), families.to_data(case, 1)


def diagnosis_benchmark(pool) -> float:
    from panto.identification.diagnosis.benchmark import run_diagnosis_benchmark

    started = time.perf_counter()
    run_diagnosis_benchmark(4, seed=3, executor=pool, duration=10.0)
    return time.perf_counter() - started


def multistarts(pool, train) -> float:
    from panto.identification.estimation.least_squares import fit_least_squares
    from panto.identification.structures.oscillators import OscillatorStructure

    structure = OscillatorStructure(3, outputs=train.output_names)
    started = time.perf_counter()
    fit_least_squares(structure, train, free=structure.default_free(), multistart=12,
                      rng=np.random.default_rng(0), executor=pool, max_evaluations=600)
    return time.perf_counter() - started


def comparison(pool, train, validation) -> float:
    from panto.identification.estimation.comparison import compare_structures
    from panto.identification.structures.registry import comparison_identifiers

    started = time.perf_counter()
    compare_structures(train, validation, executor=pool,
                       structures=comparison_identifiers(["physical-linear",
                                                          "three-mass-friction", "three-mass"]))
    return time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    """Time every path at every worker count; write the .json and .md."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    arguments = parser.parse_args(argv)
    train, validation = _data()
    load = os.getloadavg()
    rows: dict[str, dict[int, float]] = {"diagnosis benchmark (4 cases)": {},
                                         "multistarts (12 runs)": {},
                                         "structure comparison (3 structures)": {}}
    for workers in arguments.workers:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            pool.submit(int, 0).result()  # the processes are up before the clocks start
            rows["diagnosis benchmark (4 cases)"][workers] = diagnosis_benchmark(pool)
            rows["multistarts (12 runs)"][workers] = multistarts(pool, train)
            rows["structure comparison (3 structures)"][workers] = comparison(pool, train,
                                                                                validation)
        print(f"{workers} worker(s): " + ", ".join(f"{k} {v[workers]:.1f} s"
                                                    for k, v in rows.items()), flush=True)
    out = HERE / "scale_out"
    report = {"machine": f"{platform.platform()}, {os.cpu_count()} CPUs",
              "load_before": load, "load_after": os.getloadavg(),
              "seconds": {k: {str(w): s for w, s in v.items()} for k, v in rows.items()}}
    out.with_suffix(".json").write_text(json.dumps(report, indent=1))
    workers = arguments.workers
    lines = ["# Scale-out: speed-up per worker process", "",
             f"`OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/scale_out.py --workers "
             f"{' '.join(map(str, workers))}`; {report['machine']}; load average before "
             f"{load[0]:.1f}, after {report['load_after'][0]:.1f}.", "",
             "| path | " + " | ".join(f"{w} worker(s) [s] (speed-up)" for w in workers) + " |",
             "|---" * (len(workers) + 1) + "|"]
    for name, seconds in rows.items():
        base = seconds[workers[0]]
        lines.append(f"| {name} | " + " | ".join(
            f"{seconds[w]:.1f} ({base / seconds[w]:.2f}x)" for w in workers) + " |")
    out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
