"""Benchmark: the pantograph design proven on the virtual test bed (issue 7, thesis section 5.5).

Run by hand; writes benchmarks/doe_pantograph.json and benchmarks/doe_pantograph.md (and the runs
into a temporary folder, or ``--out``).

    .venv/bin/python benchmarks/doe_pantograph.py [--duration 60] [--generations 150]

What it does: ``panto doe``'s design (D-optimal, ``physical-linear``, the free parameters
below, rig limits from the rig's profile, drive and pressure loop) for ``--duration`` seconds;
the designed profile and the APRBS training profile of equal length are run on the virtual test
bed (the Pantograph FMU at the nominal parameters, every rig imperfection off except the sensor
noise: the comparison is about information); the free parameters are identified from each run by
Levenberg-Marquardt (:func:`panto.identification.estimation.least_squares.fit_least_squares`, 50 Hz, outputs F_c
and y_cb, start at 1.1 x the truth); reported: the covariance ratio (det per parameter, std
ratios) designed vs APRBS, and whether the truth lies in each 95 % interval.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))

from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.pantograph import DesignOptions, design_pantograph_experiment
from panto.identification.design.profiles import VirtualRigOptions, compare_on_virtual_rig
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

FREE = ("m_c", "c_c", "k_c", "k_p", "c1", "m1")


def run(duration: float, generations: int, population: int, out: Path, seed: int) -> dict:
    """Design, run both inputs on the virtual test bed, identify; the result as a dict."""
    constraints = RigInputConstraints.from_rig()
    n = int(round(duration / constraints.sample_period))
    began = time.perf_counter()
    model = LinearisedPantograph("physical-linear", free=FREE, length=n,
                                 operating_point=constraints.operating_point(),
                                 sample_period=constraints.sample_period,
                                 pressure_lag=constraints.pressure_lag)
    design = design_pantograph_experiment(model, constraints,
                                          options=DesignOptions(population, generations, seed))
    design_time = time.perf_counter() - began
    began = time.perf_counter()
    comparison = compare_on_virtual_rig(design, out, options=VirtualRigOptions(seed=seed),
                                        progress=lambda line: print(line, flush=True))
    return {"date": datetime.now(UTC).isoformat(timespec="seconds"),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                       f"Python {platform.python_version()}",
            "load_average": [round(v, 2) for v in os.getloadavg()],
            "design_s": design_time, "runs_and_fits_s": time.perf_counter() - began,
            "design": design.summary(), "virtual": comparison.summary(),
            "markdown": comparison.markdown()}


def markdown(result: dict) -> str:
    """The benchmark as a Markdown report."""
    design = result["design"]
    predicted = ", ".join(f"{r['parameter']} {r['ratio_conventional_to_designed']:.2f}"
                          for r in design["table"])
    return "\n".join([
        "# Pantograph design on the virtual test bed (issue 7, thesis 5.5)", "",
        f"{result['date']}, {result['machine']}, load average {result['load_average']}", "",
        f"Design: {design['message']}, {result['design_s']:.1f} s; runs and fits "
        f"{result['runs_and_fits_s']:.1f} s. Least predicted contact force "
        f"{design['min_contact_force_N']:.1f} N.", "",
        f"Predicted std ratio APRBS / designed: {predicted}.", "",
        "Identified on the virtual test bed (sensor noise only):", "",
        result["markdown"]])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--generations", type=int, default=150)
    parser.add_argument("--population", type=int, default=40)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", help="folder for the runs (default: a temporary folder)")
    args = parser.parse_args()
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="doe_pantograph_"))
    result = run(args.duration, args.generations, args.population, out, args.seed)
    (HERE / "doe_pantograph.json").write_text(json.dumps(result, indent=2, default=float))
    (HERE / "doe_pantograph.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
