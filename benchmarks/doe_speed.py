"""Benchmark: design of experiments on this machine (thesis section 5.4 example, issue 7).

Run by hand; writes benchmarks/doe_speed.json and benchmarks/doe_speed.md (and the example's
plots and summary into docs/doe/).

    .venv/bin/python benchmarks/doe_speed.py [--generations 300] [--online-generations 12]

Measures, for the one-mass oscillator (m, c, k = 1, 2, 20; Ts = 0.1 s; T_end = 30 s; N = 300):

* the full offline design (pymoo GA, population 60, ``--generations`` generations, D-optimal),
* the online design (RLS + receding horizon of 20 inputs, GA of population 20 and
  ``--online-generations`` generations per sample): time per step (mean, 95 %, max) against the
  sample period,
* one vectorised criterion evaluation of a population of 60 whole inputs (N = 300),

and records the outcome of the example: Cramer-Rao variance ratios sine / design at the true
parameters, the RLS estimates and P matrices (eqs. 5.26-5.28) and the grey-box m, c, k
(Table 5.1). Machine load is recorded: other processes on the same cores slow every number.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
# one BLAS thread: small matrices, and on a loaded machine threads spinning cost 10x (measured)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

from panto.identification.design.thesis_example import run_thesis_example
from panto.identification.design.oscillator import (
    INITIAL_PHYSICAL,
    NOISE_VARIANCE,
    TransferFunctionModel,
    discretise_oscillator,
    two_sine_input,
)
from panto.identification.design.plots import plot_line_designs, plot_thesis_example
from panto.identification.design.fisher import criterion_cost, fisher_information
from panto.identification.design.input_design import GeneticOptions
from panto.identification.design.online_design import OnlineOptions


def time_population_evaluation(repeats: int = 50) -> float:
    """Seconds for one D-criterion evaluation of 60 candidate inputs of 300 samples."""
    model = TransferFunctionModel()
    theta = discretise_oscillator(*INITIAL_PHYSICAL)
    population = np.tile(two_sine_input(), (60, 1))[..., None]
    began = time.perf_counter()
    for _ in range(repeats):
        _, psi = model.sensitivities(theta, population)
        criterion_cost(fisher_information(psi, NOISE_VARIANCE), "D")
    return (time.perf_counter() - began) / repeats


def time_pantograph(generations: int = 60, online_steps: int = 50) -> dict:
    """Pantograph case (thesis 5.5): a full offline D-optimal design of 60 s at 50 Hz for six
    parameters of the linearised physical model, and receding-horizon online steps (horizon 20
    samples of both inputs, GA population 20 x 12 generations) on a 2.4 s sensitivity window,
    the information of older samples kept as a fixed prior, against the 20 ms sample period."""
    from panto.identification.design.input_design import (DesignProblem, InputConstraints,
                                                          SequenceRepair, run_genetic)
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph import (DesignOptions, design_pantograph_experiment,
                                                         model_inputs)
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    free = ("m_c", "c_c", "k_c", "k_p", "c1", "m1")
    rig = RigInputConstraints.from_rig()
    began = time.perf_counter()
    model = LinearisedPantograph("physical-linear", free=free, length=3000,
                                 pressure_lag=rig.pressure_lag)
    build = time.perf_counter() - began
    design = design_pantograph_experiment(model, rig, options=DesignOptions(40, generations))
    horizon, window = 20, 120
    short = LinearisedPantograph("physical-linear", free=free, length=window + horizon,
                                 pressure_lag=rig.pressure_lag)
    limits = InputConstraints((2.0 + rig.motor_min, rig.pressure_min),
                              (2.0 + rig.motor_max, rig.pressure_max),
                              (rig.motor_speed * rig.sample_period, rig.pressure_max),
                              (2.0, rig.pressure_start))
    past_all = model_inputs(design.motor_position, design.pressure_demand, rig)
    variance = model.noise_variance_default()
    steps = []
    for k in range(window, window + online_steps):
        prior = model.fisher(past_all[:k - window + 1], variance) + 1e-9 * np.eye(len(free))
        tick = time.perf_counter()
        past = past_all[k - window:k]
        problem = DesignProblem(short, short.theta, limits, (horizon, 2), "D", variance,
                                 past, past[-1], prior)
        repair = SequenceRepair(limits, (horizon, 2), past[-1])
        run_genetic(problem, np.zeros((1, 2 * horizon)), GeneticOptions(20, 12, seed=k),
                     repair, limits.arrays()[2])
        steps.append(time.perf_counter() - tick)
    steps = np.array(steps)
    summary = design.summary()
    return {"offline_s": design.wall_time, "model_build_s": build,
            "offline_message": design.message, "det_ratio_per_parameter":
            summary["det_ratio_per_parameter"],
            "std_ratio": {r["parameter"]: r["ratio_conventional_to_designed"]
                          for r in summary["table"]},
            "online_mean_step_s": float(steps.mean()),
            "online_p95_step_s": float(np.percentile(steps, 95)),
            "online_max_step_s": float(steps.max()),
            "online_within_period": float(np.mean(steps < rig.sample_period))}


def time_pantograph_online(samples: int = 150) -> list[dict]:
    """The public receding-horizon step (:func:`panto.identification.design.pantograph_online.
    design_online_step`: SLSQP, exact gradient, warm start, every rig limit incl. acceleration
    and contact force) in closed loop on the linearised physical model, 6 parameters, per
    horizon / move-block setting: seconds per step against the 20 ms period at 50 Hz."""
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph_online import OnlineDesigner, run_online_design
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    rig = RigInputConstraints.from_rig()
    model = LinearisedPantograph("physical-linear", free=("m_c", "c_c", "k_c", "k_p", "c1", "m1"),
                                 length=400, pressure_lag=rig.pressure_lag)
    rows = []
    for horizon, block in ((20, 4), (20, 2), (10, 2)):
        designer = OnlineDesigner(model, rig, horizon=horizon, memory=150, block=block)
        motor, demand, steps = run_online_design(designer, samples)
        rows.append({"horizon": horizon, "block": block, "variables": 2 * designer.n_blocks,
                     "mean_step_s": float(steps.mean()),
                     "p95_step_s": float(np.percentile(steps, 95)),
                     "max_step_s": float(steps.max()),
                     "within_period": float(np.mean(steps < rig.sample_period)),
                     "violations": rig.violations(motor, demand)})
    return rows


def online_markdown(rows: list[dict]) -> str:
    """The public online step's timing as Markdown."""
    lines = ["", "## Pantograph online step (design_online_step, SLSQP, 1 BLAS thread)", "",
             "| horizon | block | variables | mean | 95 % | max | within 20 ms |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['horizon']} | {r['block']} | {r['variables']} | "
                     f"{1e3 * r['mean_step_s']:.1f} ms | {1e3 * r['p95_step_s']:.1f} ms | "
                     f"{1e3 * r['max_step_s']:.1f} ms | {100 * r['within_period']:.0f} % |")
    return "\n".join(lines) + "\n"


def pantograph_markdown(result: dict) -> str:
    """The pantograph part of the report."""
    p = result["pantograph"]
    ratios = ", ".join(f"{k} {v:.2f}" for k, v in p["std_ratio"].items())
    return "\n".join([
        "", "## Pantograph (thesis 5.5): physical-linear, 6 parameters, 60 s at 50 Hz", "",
        "| what | time |", "|---|---|",
        f"| sensitivity model build (13 linearisations) | {p['model_build_s']:.2f} s |",
        f"| full offline design ({p['offline_message']}) | {p['offline_s']:.1f} s |",
        f"| online step, horizon 20, window 2.4 s, mean | {1e3 * p['online_mean_step_s']:.1f} ms |",
        f"| online step, 95th percentile | {1e3 * p['online_p95_step_s']:.1f} ms |",
        f"| online steps within the 20 ms sample period | {100 * p['online_within_period']:.0f} % |",
        "", f"Predicted std ratio APRBS / designed: {ratios}; det ratio per parameter "
        f"{p['det_ratio_per_parameter']:.2f}.", ""])


def markdown(result: dict) -> str:
    """The benchmark as a Markdown report."""
    online, offline, example = result["online"], result["offline"], result["example"]
    lines = [
        "# Design of experiments: speed and outcome (thesis section 5.4)", "",
        f"{result['date']}, {result['machine']}, load average {result['load_average']}", "",
        "| what | time |", "|---|---|",
        (f"| criterion of 60 inputs x 300 samples (one GA generation) | "
         f"{1e3 * result['population_evaluation_s']:.2f} ms |"),
        f"| full offline design ({offline['message']}) | {offline['wall_time_s']:.1f} s |",
        f"| online step, horizon 20, mean | {1e3 * online['mean_step_s']:.1f} ms |",
        f"| online step, 95th percentile | {1e3 * online['p95_step_s']:.1f} ms |",
        f"| online step, max | {1e3 * online['max_step_s']:.1f} ms |",
        f"| online steps within the sample period (100 ms) | {100 * online['within_period']:.1f} % |",
        f"| whole online run (300 samples) | {online['wall_time_s']:.1f} s |", "",
        "Cramer-Rao variance ratio sine / input at the true parameters (a1, a2, b1, b2):", "",
        "| input | a1 | a2 | b1 | b2 | grey-box m, c, k | grey-box variances |",
        "|---|---|---|---|---|---|---|"]
    for name, values in example["inputs"].items():
        ratio = " | ".join(f"{r:.1f}" for r in values["variance_ratio_vs_sine"])
        mck = ", ".join(f"{v:.4f}" for v in values["grey_box_m_c_k"])
        var = ", ".join(f"{v:.2e}" for v in values["grey_box_variance"])
        lines.append(f"| {name} | {ratio} | {mck} | {var} |")
    lines += ["", "RLS estimate and P (from theta_init, P0 = 1e6 I), as eqs. 5.26-5.28:", ""]
    for name, values in example["inputs"].items():
        lines.append(f"- {name}: theta = {np.round(values['rls_theta'], 4).tolist()}, "
                     f"diag P = {np.round(np.diag(values['rls_P']), 2).tolist()}")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generations", type=int, default=300)
    parser.add_argument("--online-generations", type=int, default=12)
    parser.add_argument("--online-only", action="store_true",
                        help="only (re-)measure the pantograph online step; keep the rest")
    parser.add_argument("--pantograph-only", action="store_true",
                        help="only (re-)measure the pantograph case; keep the rest of the file")
    args = parser.parse_args()
    if args.online_only:
        result = json.loads((HERE / "doe_speed.json").read_text())
        result["pantograph_online"] = time_pantograph_online()
        result["load_average_online"] = [round(v, 2) for v in os.getloadavg()]
        (HERE / "doe_speed.json").write_text(json.dumps(result, indent=2))
        (HERE / "doe_speed.md").write_text(markdown(result) + pantograph_markdown(result)
                                           + online_markdown(result["pantograph_online"]))
        print(online_markdown(result["pantograph_online"]))
        return
    if args.pantograph_only:
        result = json.loads((HERE / "doe_speed.json").read_text())
        result["pantograph"] = time_pantograph()
        result["load_average_pantograph"] = [round(v, 2) for v in os.getloadavg()]
        (HERE / "doe_speed.json").write_text(json.dumps(result, indent=2))
        (HERE / "doe_speed.md").write_text(markdown(result) + pantograph_markdown(result))
        print(pantograph_markdown(result))
        return
    evaluation = time_population_evaluation()
    example = run_thesis_example(
        offline_options=GeneticOptions(population=60, generations=args.generations),
        online_options=OnlineOptions(genetic=GeneticOptions(20, args.online_generations)),
        progress=lambda line: print(line, flush=True))
    steps = example.online.step_times
    summary = example.summary()
    result = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
                   f"Python {platform.python_version()}",
        "load_average": [round(v, 2) for v in os.getloadavg()],
        "population_evaluation_s": evaluation,
        "offline": summary["offline"],
        "online": {**summary["online"], "p95_step_s": float(np.percentile(steps, 95)),
                   "within_period": float(np.mean(steps < 0.1))},
        "example": summary,
        "pantograph": time_pantograph(),
        "pantograph_online": time_pantograph_online(),
    }
    (HERE / "doe_speed.json").write_text(json.dumps(result, indent=2))
    (HERE / "doe_speed.md").write_text(markdown(result) + pantograph_markdown(result)
                                       + online_markdown(result["pantograph_online"]))
    docs = HERE.parent / "docs" / "doe"
    plot_line_designs(docs / "doe_line.png")
    plot_thesis_example(example, docs)
    example.write(docs)
    print(markdown(result))


if __name__ == "__main__":
    main()
