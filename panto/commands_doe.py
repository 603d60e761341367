"""``panto doe``: design the next rig run (thesis chapter 5 and the pantograph rig's designs).

* ``panto doe --model physical-linear [--parameters FILE] [--free ...] [--duration 60]
  [--criterion D|A|E] [--population N --generations N] [--out FOLDER] [--json FILE]``: the
  optimal motor position and pressure demand for the structure's free parameters, written as a
  rig profile (JSON + CSV table, checked by the profile loader), the predicted covariance table
  (designed vs the APRBS training profile of equal length) and plots
  (:mod:`panto.identification.design.constraints`, :mod:`panto.identification.design.pantograph`,
  :mod:`panto.identification.design.profiles`).
* ``--discriminate EFFECT`` (``F_f1``: friction on the two-mass oscillator's lower mass;
  ``T_f``: hinge friction in the nonlinear pantograph FMU): the input that makes the effect
  show (T-optimality, :mod:`panto.identification.design.discrimination`), exported the same way.
* ``--thesis-example``: the thesis' section 5.4 example (:mod:`panto.identification.design.thesis_example`)
  with its plots.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

from panto.console import say


def register(add: Callable) -> None:
    """Declare ``panto doe`` with ``add(name, handler, help)``."""
    p = add("doe", run_doe, "design the next rig run: D/A/E-optimal inputs for a pantograph "
            "structure or a discrimination input, as a rig profile (thesis chapter 5)")
    p.add_argument("--model", default="physical-linear",
                   choices=("physical-linear", "two-mass", "three-mass"))
    p.add_argument("--parameters", help="parameter file (e.g. an identification's "
                   "parameters.json); default: the structure's nominal values")
    p.add_argument("--free", nargs="+", help="parameters to design for (default: the "
                   "structure's free parameters)")
    p.add_argument("--duration", type=float, default=60.0, help="run length [s] (60)")
    p.add_argument("--criterion", choices=("D", "A", "E"), default="D")
    p.add_argument("--discriminate", choices=("F_f1", "T_f"),
                   help="design to detect this effect instead (F_f1 uses --model two-mass, T_f "
                   "the nonlinear pantograph)")
    p.add_argument("--effect-size", type=float, help="size of the effect (N or N m)")
    p.add_argument("--population", type=int, help="GA population (40; 12 for --discriminate)")
    p.add_argument("--generations", type=int, help="GA generations (150; 15 for --discriminate)")
    p.add_argument("--minimum-contact-force", type=float, default=20.0,
                   help="least predicted contact force [N] (20)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="doe_design", help="output folder (doe_design)")
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.add_argument("--thesis-example", action="store_true",
                   help="run the thesis' section 5.4 example and write its plots into --out")


def read_parameters(path: str | Path) -> dict[str, float]:
    """``{name: value}`` from a parameter file (``{"parameters": {name: {"value": v}}}`` or
    ``{name: v}``)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as error:
        raise SystemExit(f"{path}: cannot read the parameter file ({error})") from None
    entries = data.get("parameters", data) if isinstance(data, dict) else None
    if not isinstance(entries, dict):
        raise SystemExit(f"{path}: expected an object with a 'parameters' object")
    values = {}
    for name, entry in entries.items():
        value = entry.get("value") if isinstance(entry, dict) else entry
        if not isinstance(value, (int, float)):
            raise SystemExit(f"{path}: parameter {name!r} has no numeric value ({entry!r})")
        values[name] = float(value)
    return values


def _model(args: argparse.Namespace, constraints, n_samples: int):
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    structure = args.model
    if args.discriminate == "F_f1":
        structure = "two-mass"
    elif args.discriminate == "T_f":
        structure = "physical-linear"
    values = read_parameters(args.parameters) if args.parameters else {}
    probe = LinearisedPantograph.structure_for(structure)
    parameters = {k: v for k, v in values.items() if k in probe.parameter_names}
    fixed = {k: v for k, v in values.items() if k not in probe.parameter_names} \
        if structure == "physical-linear" else {}
    free = args.free
    if free is None and structure == "two-mass":
        free = [n for n in probe.default_free() if n != "y_0"]
    return LinearisedPantograph(structure, parameters, free, fixed=fixed,
                                operating_point=constraints.operating_point(),
                                sample_period=constraints.sample_period, length=n_samples,
                                pressure_lag=constraints.pressure_lag)


def run_doe(args: argparse.Namespace) -> int:
    """Dispatch (module notes)."""
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.thesis_example:
        return _thesis_example(out)
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph import DesignOptions

    constraints = RigInputConstraints.from_rig(minimum_contact_force=args.minimum_contact_force)
    n_samples = int(round(args.duration / constraints.sample_period))
    model = _model(args, constraints, n_samples)
    say(f"{model.structure_name}: designing for {list(model.parameter_names)}, "
        f"{args.duration} s, rig limits {constraints}")
    if args.discriminate:
        return _discriminate(args, model, constraints, out)
    from panto.identification.design.pantograph import design_pantograph_experiment
    from panto.identification.design.profiles import write_design_report

    options = DesignOptions(population=args.population or 40,
                            generations=args.generations or 150, seed=args.seed)
    design = design_pantograph_experiment(model, constraints, criterion=args.criterion,
                                          options=options, progress=say)
    paths = write_design_report(design, out)
    say(f"{'parameter':>10} {'value':>12} {'std designed':>14} {'std APRBS':>12} {'ratio':>7}")
    for row in design.covariance_table():
        say(f"{row['parameter']:>10} {row['value']:12.5g} {row['std_designed']:14.4g} "
            f"{row['std_conventional']:12.4g} {row['ratio_conventional_to_designed']:7.2f}")
    return _finish(args, design.summary(), paths)


def _discriminate(args, model, constraints, out: Path) -> int:
    from panto.identification.design.pantograph import DesignOptions
    from panto.identification.design.discrimination import EffectModel, design_discrimination
    from panto.identification.design.profiles import write_design_profile

    options = DesignOptions(population=args.population or 12,
                            generations=args.generations or 15, seed=args.seed)
    effect = EffectModel(args.discriminate, model, args.effect_size)
    design = design_discrimination(effect, constraints, options=options, progress=say)
    profile, table = write_design_profile(
        design.motor_position, design.pressure_demand, constraints, out,
        name=f"discriminate_{args.discriminate}",
        notes=f"T-optimal input to detect {args.discriminate} = {effect.value} (panto doe)")
    summary = design.summary()
    say(f"T criterion: designed {summary['T_designed']:.4g}, APRBS "
        f"{summary['T_conventional']:.4g} (ratio {summary['ratio']:.2f})")
    (out / "discrimination_summary.json").write_text(json.dumps(summary, indent=2, default=float)
                                                     + "\n")
    return _finish(args, summary, {"profile": profile, "table": table})


def _finish(args, summary: dict, paths: dict) -> int:
    for name, path in paths.items():
        say(f"wrote {name}: {path}")
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=2, default=float) + "\n")
        say(f"wrote {args.json}")
    return 0


def _thesis_example(out: Path) -> int:
    from panto.identification.design.thesis_example import run_thesis_example
    from panto.identification.design.plots import plot_line_designs, plot_thesis_example

    example = run_thesis_example(progress=say)
    paths = [plot_line_designs(out / "doe_line.png"), *plot_thesis_example(example, out),
             *example.write(out)]
    for path in paths:
        say(f"wrote {path}")
    return 0
