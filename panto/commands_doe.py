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
* ``--closed-loop``: the loop of thesis section 5.5 on the virtual test bed
  (:mod:`panto.identification.design.closed_loop`): identify from an APRBS run, design run 2 at
  that estimate, run it, re-identify from both runs; writes ``closed_loop.json``,
  ``closed_loop.md`` (predicted vs achieved std per parameter, verdicts before and after) and
  ``closed_loop.png``. ``--repeat`` runs the APRBS again instead of the design (the control).
* ``--thesis-example``: the thesis' section 5.4 example (:mod:`panto.identification.design.thesis_example`)
  with its plots.
"""
from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

from panto.console import progress, say, write_json
from panto.data_options import UsageError, non_negative_int, positive_float, positive_int


def register(add: Callable) -> None:
    """Declare ``panto doe`` with ``add(name, handler, help)``."""
    p = add("doe", run_doe, "design the next rig run: D/A/E-optimal inputs for a pantograph "
            "structure or a discrimination input, as a rig profile (thesis chapter 5)")
    p.add_argument("--model", default="physical-linear",
                   choices=("physical-linear", "two-mass", "three-mass"),
                   help="structure designed for (default physical-linear)")
    p.add_argument("--parameters", help="parameter file (e.g. an identification's "
                   "parameters.json); default: the structure's nominal values")
    p.add_argument("--free", nargs="+", help="parameters to design for (default: the "
                   "structure's free parameters)")
    p.add_argument("--duration", type=positive_float, default=60.0, help="run length [s] (60)")
    p.add_argument("--criterion", choices=("D", "A", "E"), default="D",
                   help="optimality criterion of the covariance (default D)")
    p.add_argument("--discriminate", choices=("F_f1", "T_f"),
                   help="design to detect this effect instead (F_f1 uses --model two-mass, T_f "
                   "the nonlinear pantograph)")
    p.add_argument("--effect-size", type=float, help="size of the effect (N or N m)")
    p.add_argument("--population", type=positive_int,
                   help="GA population (40; 12 for --discriminate)")
    p.add_argument("--generations", type=positive_int,
                   help="GA generations (150; 15 for --discriminate)")
    p.add_argument("--minimum-contact-force", type=float, default=20.0,
                   help="least predicted contact force [N] (20)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the GA (0)")
    p.add_argument("--out", default="doe_design", help="output folder (doe_design)")
    p.add_argument("--json", help="also write the summary to this JSON file")
    p.add_argument("--thesis-example", action="store_true",
                   help="run the thesis' section 5.4 example and write its plots into --out")
    loop = p.add_argument_group("closed loop (thesis 5.5 on the virtual test bed)")
    loop.add_argument("--closed-loop", action="store_true",
                      help="identify from an APRBS run of --duration, design run 2 there, run it "
                      "on the virtual test bed, re-identify from both: predicted vs achieved std")
    loop.add_argument("--repeat", action="store_true",
                      help="with --closed-loop: run 2 repeats the APRBS (the control)")
    loop.add_argument("--fmu", help="the plant's Pantograph FMU (default: the project's)")
    loop.add_argument("--true-parameters", help="the plant's parameter file (default: the "
                      "FMU's values)")
    loop.add_argument("--start-factor", type=float, default=1.1,
                      help="without --parameters the fit starts at the plant's values times this "
                      "(1.1)")
    loop.add_argument("--outputs", nargs="+", default=["F_c", "y_cb"], choices=("F_c", "y_cb"),
                      help="outputs fitted and designed for (F_c y_cb)")


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
    return _in_model_units(path, data.get("model"), values)


#: The fmu_src model whose parameter file each designed structure reads.
FILE_MODELS = {"physical-linear": "Pantograph", "two-mass": "TwoMass", "three-mass": "ThreeMass"}


def _in_model_units(path: Path, model: str | None, values: dict[str, float]) -> dict[str, float]:
    """`values` with units converted (or refused) as the named model's parameter file says."""
    from panto.fmu_src.models import FMU_NAMES, default_parameters
    from panto.fmu_src.parameters import ParameterSet

    if model not in FMU_NAMES:
        return values
    loaded = ParameterSet.load(path, default_parameters(model).specs, model)  # units, bounds
    return {name: float(loaded.values.get(name, value)) for name, value in values.items()}


def _check_file_model(path: str, structure: str, values: dict[str, float], known) -> None:
    """A parameter file for another model, or with names the structure lacks, is refused."""
    model = json.loads(Path(path).read_text(encoding="utf-8")).get("model")
    if model is not None and model != FILE_MODELS.get(structure, model):
        raise ValueError(f"--parameters {path}: parameters are for model {model!r}; {structure} "
                         f"reads a {FILE_MODELS[structure]!r} file")
    unknown = sorted(set(values) - set(known))
    if unknown and structure != "physical-linear":
        raise ValueError(f"--parameters {path}: {unknown} are not parameters of {structure} "
                         f"(its: {', '.join(known)})")


def _model(args: argparse.Namespace, constraints, n_samples: int):
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    structure = args.model
    if args.discriminate == "F_f1":
        structure = "two-mass"
    elif args.discriminate == "T_f":
        structure = "physical-linear"
    values = read_parameters(args.parameters) if args.parameters else {}
    probe = LinearisedPantograph.structure_for(structure)
    if args.parameters:
        _check_file_model(args.parameters, structure, values, probe.parameter_names)
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
    if args.closed_loop:
        return _closed_loop(args, out)
    if args.repeat or args.fmu or args.true_parameters:
        raise UsageError("--repeat, --fmu and --true-parameters need --closed-loop")
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph import DesignOptions

    constraints = RigInputConstraints.from_rig(minimum_contact_force=args.minimum_contact_force)
    n_samples = int(round(args.duration / constraints.sample_period))
    model = _model(args, constraints, n_samples)
    say(f"{model.structure_name}: designing for {list(model.parameter_names)}, "
        f"{args.duration} s, rig limits: {constraints.describe()}")
    if args.discriminate:
        return _discriminate(args, model, constraints, out)
    from panto.identification.design.pantograph import design_pantograph_experiment
    from panto.identification.design.profiles import write_design_report

    options = DesignOptions(population=args.population or 40,
                            generations=args.generations or 150, seed=args.seed)
    design = design_pantograph_experiment(model, constraints, criterion=args.criterion,
                                          options=options, progress=progress)
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
    design = design_discrimination(effect, constraints, options=options, progress=progress)
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
        write_json(args.json, summary, default=float)
    return 0


def _closed_loop(args: argparse.Namespace, out: Path) -> int:
    from panto.build_fmu.project import project_fmu
    from panto.fmu_src.models import default_parameters
    from panto.identification.design.closed_loop import (ClosedLoopOptions, VirtualTestBedRunner,
                                                         closed_loop_experiment,
                                                         write_closed_loop_report)
    from panto.identification.design.constraints import RigInputConstraints
    from panto.identification.design.pantograph import DesignOptions
    from panto.identification.design.pantograph_sensitivity import LinearisedPantograph

    defaults = default_parameters("Pantograph")
    plant = {n: float(defaults[n]) for n in defaults.names} | (
        read_parameters(args.true_parameters) if args.true_parameters else {})
    structure = LinearisedPantograph.structure_for(args.model)
    known = set(structure.parameter_names)
    truth = {k: v for k, v in plant.items() if k in known} if args.model == "physical-linear" \
        else {}
    options = ClosedLoopOptions(
        structure=args.model, free=tuple(args.free) if args.free else None,
        duration=args.duration, criterion=args.criterion, outputs=tuple(args.outputs),
        next_run="repeat" if args.repeat else "designed",
        design=DesignOptions(population=args.population or 40,
                             generations=args.generations or 150, seed=args.seed))
    if args.parameters:
        initial = {k: v for k, v in read_parameters(args.parameters).items() if k in known}
    else:
        start = truth or structure.nominal()
        initial = {k: args.start_factor * v for k, v in start.items()}
    runner = VirtualTestBedRunner(args.fmu or project_fmu("Pantograph"), out / "runs",
                                  parameters=plant, seed=args.seed)
    constraints = RigInputConstraints.from_rig(minimum_contact_force=args.minimum_contact_force)
    result = closed_loop_experiment(runner, options=options, constraints=constraints,
                                    initial=initial, truth=truth, progress=progress)
    say(result.markdown())
    return _finish(args, result.summary(), write_closed_loop_report(result, out))


def _thesis_example(out: Path) -> int:
    from panto.identification.design.thesis_example import run_thesis_example
    from panto.identification.design.plots import plot_line_designs, plot_thesis_example

    example = run_thesis_example(progress=progress)
    paths = [plot_line_designs(out / "doe_line.png"), *plot_thesis_example(example, out),
             *example.write(out)]
    for path in paths:
        say(f"wrote {path}")
    return 0
