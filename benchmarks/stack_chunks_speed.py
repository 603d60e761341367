"""Benchmark: test files run with and without the kept frame-stack chunks, in the same run.

    .venv/bin/python -P benchmarks/stack_chunks_speed.py [--repeat 2] [TEST ...]

Writes benchmarks/stack_chunks_speed.json and benchmarks/stack_chunks_speed.md.

Each case runs pytest on the test files (default: two of the suite's slowest diagnosis files) in
one xdist worker, as ``scripts/test`` runs them (``-n 1``: the tests' stack depth is the
suite's), with ``PANTO_KEEP_STACK_CHUNKS=0`` (``off``: CPython's own arena allocator, which maps
and unmaps a 16 KiB chunk on every call that crosses a chunk boundary) or unset (``on``:
:func:`panto.fmu_src.frame_stack.keep_stack_chunks`, installed by the tests' conftest). The cases
alternate (off, on, on, off, ...) so that a change in the machine's other work falls on both.
Per case the children's CPU time (user and system, from ``resource.getrusage``), the wall time
and pytest's outcome; the ratio off / on of the medians. Both must pass the same tests (the
allocator changes where frames live, never a value; the comparison is of pytest's counts, the
tests' own assertions check the values): exit status 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DEFAULT_TESTS = ("tests/test_diagnosis_lag_global.py", "tests/test_diagnosis_sensor_mass_global.py")


def run_case(tests: list[str], on: bool) -> dict:
    """One pytest run of `tests` in a fresh process tree: CPU, wall time and the last line."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    env.pop("PANTO_KEEP_STACK_CHUNKS", None)
    if not on:
        env["PANTO_KEEP_STACK_CHUNKS"] = "0"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-P", "-m", "pytest", "-q", "-n", "1",
                           "-p", "no:cacheprovider", *tests], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    return {"allocator": "on" if on else "off", "returncode": done.returncode,
            "outcome": lines[-1] if lines else done.stderr.strip()[-200:],
            "user_s": after.ru_utime - before.ru_utime, "sys_s": after.ru_stime - before.ru_stime,
            "wall_s": wall}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("tests", nargs="*", default=list(DEFAULT_TESTS))
    parser.add_argument("--repeat", type=int, default=2, help="pairs of cases (default 2)")
    args = parser.parse_args()
    if args.repeat < 1:
        parser.error(f"--repeat {args.repeat}: at least 1 pair of cases")
    order = [False, True, True, False] * ((args.repeat + 1) // 2)
    order = order[:2 * args.repeat]
    cases = []
    for k, on in enumerate(order):
        print(f"case {k + 1}/{len(order)}: allocator {'on' if on else 'off'}", file=sys.stderr,
              flush=True)
        cases.append(run_case(args.tests, on))
        print(f"  {cases[-1]}", file=sys.stderr, flush=True)

    def median(kind: str, key: str) -> float:
        return statistics.median(c[key] for c in cases if c["allocator"] == kind)

    summary = {key: {"off": median("off", key), "on": median("on", key),
                     "ratio_off_on": median("off", key) / max(median("on", key), 1e-9)}
               for key in ("user_s", "sys_s", "wall_s")}
    record = {"benchmark": "stack_chunks_speed", "tests": args.tests,
              "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
              "machine": {"processor": platform.processor() or platform.machine(),
                          "cpus": os.cpu_count(), "python": platform.python_version()},
              "cases": cases, "median": summary,
              "same_outcome": len({c["outcome"].split(" in ")[0] for c in cases}) == 1}
    (HERE / "stack_chunks_speed.json").write_text(json.dumps(record, indent=2) + "\n")
    rows = "\n".join(f"| {key} | {v['off']:.1f} | {v['on']:.1f} | {v['ratio_off_on']:.2f} |"
                     for key, v in summary.items())
    outcomes = "\n".join(f"- {c['allocator']}: {c['outcome']} (user {c['user_s']:.1f} s, sys "
                         f"{c['sys_s']:.1f} s, wall {c['wall_s']:.1f} s)" for c in cases)
    (HERE / "stack_chunks_speed.md").write_text(f"""# Kept frame-stack chunks: test files with and without

`{' '.join(['.venv/bin/python -P benchmarks/stack_chunks_speed.py', '--repeat',
            str(args.repeat), *args.tests])}` on {record['date']}
({record['machine']['processor']}, {record['machine']['cpus']} CPUs, Python
{record['machine']['python']}). Medians over the cases, seconds of the child processes.

| time | off (CPython's allocator) | on (chunks kept) | off / on |
|---|---|---|---|
{rows}

Same pytest outcome in every case: {record['same_outcome']}.

{outcomes}
""")
    print(json.dumps(summary), file=sys.stderr)
    # 1 when a case failed or the cases' outcomes differ (the allocator must change no result)
    return 0 if record["same_outcome"] and all(c["returncode"] == 0 for c in cases) else 1


if __name__ == "__main__":
    sys.exit(main())
