"""``panto diagnose``: where the model and the measurement disagree, which unmodelled effect causes
it, and how far the gap shrinks once it is in the model.

``panto diagnose --train TRAIN --validate VALIDATION --model STRUCTURE [--inputs NAME=CHANNEL ...]
[--outputs NAME=CHANNEL ...] [--rate HZ] [--sample-rate HZ] [--roles position=..,force=..]
[--candidates ...] [--option KEY=VALUE ...] [--out FOLDER] [--json FILE]``

- Rig runs with a pantograph structure (``physical``, ``physical-linear``, ``two-mass``, ...) and
  no ``--inputs``/``--outputs``: the rig mapping (eta, p) -> (F_c, y_cb) at ``--rate`` (50 Hz).
- Any other data (CSV, Parquet or .mat with named columns; the product's datasets or plain
  tables): ``--inputs``/``--outputs`` name the columns; a plain table without a ``time``/``t``
  column needs ``--sample-rate``; ``--rate`` decimates (zero-phase low-pass first);
  ``--train-samples``/``--validate-samples START:STOP`` select rows (e.g. two parts of one file).

The data options are :mod:`panto.data_options` (shared with ``panto identify`` and ``panto
compare``); the loading is the library's
:func:`panto.identification.data.loading.load_identification_data`.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Callable

from panto.console import progress, say, write_json
from panto.data_options import (UsageError, add_data_options, load_data, non_negative_int,
                                positive_float, positive_int)
from panto.data_options import parse_pairs as _pairs


def _value(text: str) -> Any:
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    if lowered == "none":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _load(path: str, args: argparse.Namespace, validation: bool):
    """One run's IdentificationData from the shared data options (module notes)."""
    from panto.identification.structures.registry import is_pantograph_structure

    return load_data(path, args, validation=validation,
                     rig_mapping=is_pantograph_structure(args.model))


def _roles(text: str | None):
    if not text:
        return None
    from panto.identification.diagnosis.effects import SignalRoles

    values = _pairs([text], "--roles")
    actuators = tuple(a for a in values.pop("actuators", "").split("+") if a)
    unknown = sorted(set(values) - {"position", "velocity", "acceleration", "force", "mode_drive"})
    if unknown:
        raise ValueError(f"--roles: unknown role(s) {unknown}")
    return SignalRoles(position=values.get("position"), velocity=values.get("velocity"),
                       acceleration=values.get("acceleration"), force=values.get("force"),
                       actuators=actuators, mode_drive=values.get("mode_drive"))


def run_diagnose(args: argparse.Namespace) -> int:
    """Load both runs, diagnose, print the verdict, write the report."""
    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
    from panto.identification.estimation.global_fit import GlobalFitOptions
    from panto.identification.diagnosis.report import write_report
    from panto.identification.diagnosis.effects import EFFECTS

    train = _load(args.train, args, validation=False)
    validation = _load(args.validate, args, validation=True)
    options = {k: _value(v) for k, v in _pairs(args.option, "--option").items()}
    if args.free:
        options["free"] = tuple(args.free)
    say(f"diagnose {args.model}: training {args.train} ({len(train)} samples at "
        f"{1 / train.sample_period:g} Hz), validation {args.validate} ({len(validation)} samples)")
    _check_options(args.model, train, options)
    search = DiagnosisOptions(candidates=tuple(args.candidates or EFFECTS),
                              roles=_roles(args.roles), max_effects=args.max_effects,
                              folds=args.folds,
                              global_fit=GlobalFitOptions() if args.global_fit else None)
    result = diagnose(train, validation, structure=args.model, structure_options=options,
                      options=search, progress=progress)
    say(f"verdict: {result.verdict}" + (f" ({' then '.join(result.effects)})"
                                        if result.effects else ""))
    for output in result.output_names:
        say(f"  {output}: validation fit {result.fit_before[output]:.2f} % -> "
            f"{result.fit_after[output]:.2f} %")
    say(result.summary)
    if args.out:
        paths = write_report(result, args.out, units=train.units)
        say(f"wrote {paths['html']}, {paths['markdown']} and {paths['json']}")
    if args.json:
        write_json(args.json, result.to_dict())
    return 0


def _check_options(model: str, train, options: dict[str, Any]) -> None:
    """Build the nominal once with the ``--option`` values: an option the structure does not
    take is refused by name before the diagnosis starts."""
    from panto.identification.structures.registry import build_structure

    if not options:
        return
    try:
        build_structure(model, train, options)
    except TypeError as error:
        if "keyword argument" not in str(error):
            raise
        wrong = str(error).rsplit(" ", 1)[-1]
        raise ValueError(f"--option: structure {model!r} takes no option {wrong} ({error})"
                         ) from None


def run_benchmark(args: argparse.Namespace) -> int:
    """Draw the cases, diagnose them blind in parallel, score, write JSON + markdown + PNG."""
    from concurrent.futures import ProcessPoolExecutor

    from panto.identification.diagnosis.benchmark import run_diagnosis_benchmark
    from panto.identification.diagnosis.benchmark_report import write_benchmark

    if args.cases < 1 or args.workers < 1 or args.duration <= 2.0:
        raise ValueError(f"--cases {args.cases}, --workers {args.workers}, --duration "
                         f"{args.duration}: need cases >= 1, workers >= 1, duration > 2 s")
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        result = run_diagnosis_benchmark(args.cases, args.seed, executor=pool, progress=progress,
                                         duration=args.duration, structure=args.model)
    if args.json == "-":
        raise UsageError("--json -: the benchmark writes its .md and .png beside the JSON; "
                         "give a file")
    target = Path(args.json) if args.json else Path(args.out) / "diagnosis_benchmark.json"
    paths = write_benchmark(result, target)
    say(f"wrote {paths['json']}, {paths['markdown']} and {paths['png']}")
    return 0


def register(add: Callable) -> None:
    """Declare ``diagnose`` and ``diagnose-benchmark`` with ``add(name, handler, help)``."""
    p = add("diagnose", run_diagnose, "sim-to-real gap diagnosis: where the model misses, which "
            "unmodelled effect causes it, how far adding it closes the gap on withheld data")
    p.add_argument("--train", required=True, help="training run (folder, .csv, .parquet, .mat)")
    p.add_argument("--validate", required=True, help="withheld validation run")
    p.add_argument("--model", required=True, help="nominal structure: physical, physical-linear, "
                   "two-mass, three-mass, linear-N, rigid-body")
    add_data_options(p)
    p.add_argument("--roles", help="position=..,velocity=..,force=..,actuators=a+b")
    p.add_argument("--candidates", nargs="*", help="subset of the effect vocabulary")
    p.add_argument("--free", nargs="*", help="free parameters of the nominal")
    p.add_argument("--option", nargs="*", help="structure option KEY=VALUE (e.g. centre=true, "
                   "cutoff=0.2, input_delay=1)")
    p.add_argument("--max-effects", type=non_negative_int, default=3,
                   help="most effects added one after another (default 3)")
    p.add_argument("--folds", type=positive_int, default=4,
                   help="blocks of the validation run for the fold statistics (default 4)")
    p.add_argument("--global-fit", action="store_true",
                   help="fit the nominal from the data's frequency response and several starts, "
                        "and say whether the global optimum was found (slower)")
    p.add_argument("--out", help="folder for report.html, report.json and the plots")
    p.add_argument("--json", help="also write the JSON summary here")

    b = add("diagnose-benchmark", run_benchmark, "blind benchmark of the diagnosis on the virtual "
            "test bed: hidden effects of random magnitude, confusion matrix and scores")
    b.add_argument("--cases", type=positive_int, required=True, help="number of cases drawn")
    b.add_argument("--seed", type=non_negative_int, default=0, help="seed of the draw")
    b.add_argument("--workers", type=positive_int, default=2, help="processes running the cases")
    b.add_argument("--duration", type=positive_float, default=25.0, help="length of each run [s]")
    b.add_argument("--model", default="physical-linear", help="nominal structure")
    b.add_argument("--out", default=".", help="folder for diagnosis_benchmark.json/.md/.png")
    b.add_argument("--json", help="JSON path (the .md and _confusion.png go beside it)")
