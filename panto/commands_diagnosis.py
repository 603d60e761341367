"""``panto diagnose``: where the model and the measurement disagree, which unmodelled effect causes
it, and how far the gap shrinks once it is in the model.

``panto diagnose --train TRAIN --validate VALIDATION --model STRUCTURE [--inputs NAME=CHANNEL ...]
[--outputs NAME=CHANNEL ...] [--rate HZ] [--sample-rate HZ] [--roles position=..,force=..]
[--candidates ...] [--option KEY=VALUE ...] [--max-evaluations N] [--workers N] [--out FOLDER]
[--json FILE]``

- Rig runs with a pantograph structure (``physical``, ``physical-linear``, ``two-mass``, ...) and
  no ``--inputs``/``--outputs``: the rig mapping (eta, p) -> (F_c, y_cb) at ``--rate`` (50 Hz).
- Any other data (CSV, Parquet or .mat with named columns; the product's datasets or plain
  tables): ``--inputs``/``--outputs`` name the columns; a plain table without a ``time``/``t``
  column needs ``--sample-rate``; ``--rate`` decimates (zero-phase low-pass first);
  ``--train-samples``/``--validate-samples START:STOP`` select rows (e.g. two parts of one file).

- ``--option KEY=VALUE``: the nominal structure's options, checked against its constructor
  before the diagnosis starts (an unknown key, or a value of the wrong kind, is refused naming the
  key, the value and what the structure takes); ``--candidates`` must name effects of the
  vocabulary and ``--roles`` known roles (usage errors, code 2), whose signals must be in the
  data (bad input, 65); ``--max-evaluations`` and ``--workers`` cap each fit's simulations and
  the processes of a round's refits.

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


#: The ``--roles`` a signal can play (:class:`~panto.identification.diagnosis.effects.SignalRoles`).
ROLES = ("position", "velocity", "acceleration", "force", "mode_drive", "sensor_position",
         "actuators")
#: Option kinds a ``--option`` value can take, by the name in a constructor's annotation.
_KINDS = {"bool": "true or false", "int": "an integer", "float": "a number", "str": "a name",
          "None": "none"}


def _load(path: str, args: argparse.Namespace, validation: bool):
    """One run's IdentificationData from the shared data options (module notes)."""
    from panto.identification.structures.registry import is_pantograph_structure

    return load_data(path, args, validation=validation,
                     rig_mapping=is_pantograph_structure(args.model))


def _candidates(names: list[str] | None) -> tuple[str, ...]:
    """The ``--candidates`` (all effects when none named); an unknown name is a usage error
    listing the vocabulary."""
    from panto.identification.diagnosis.effects import EFFECTS

    unknown = [n for n in names or () if n not in EFFECTS]
    if unknown:
        raise UsageError(f"--candidates: unknown effect(s) {', '.join(map(repr, unknown))}; the "
                         f"vocabulary is {', '.join(EFFECTS)}")
    return tuple(names or EFFECTS)


def _role_values(text: str | None) -> dict[str, str] | None:
    """``--roles`` as role -> signal(s); an unknown role is a usage error listing the roles."""
    if not text:
        return None
    values = _pairs([text], "--roles")
    unknown = [r for r in values if r not in ROLES]
    if unknown:
        raise UsageError(f"--roles: unknown role(s) {', '.join(map(repr, unknown))}; the roles "
                         f"are {', '.join(ROLES)}")
    return values


def _roles(values: dict[str, str] | None, train):
    """The :class:`SignalRoles` of ``--roles``; a signal the data lacks is refused (bad input)."""
    if values is None:
        return None
    from panto.identification.diagnosis.effects import SignalRoles

    values = dict(values)
    actuators = tuple(a for a in values.pop("actuators", "").split("+") if a)
    signals = (*train.input_names, *train.output_names)
    missing = [f"{role}={name}" for role, name in [*values.items(), *(("actuators", a)
                                                                     for a in actuators)]
               if name not in signals]
    if missing:
        raise ValueError(f"--roles {', '.join(missing)}: no such signal; the data's signals "
                         f"are {', '.join(signals)}")
    unset = dict.fromkeys(("position", "velocity", "acceleration", "force", "mode_drive"))
    return SignalRoles(**{**unset, **values}, actuators=actuators)


def run_diagnose(args: argparse.Namespace) -> int:
    """Load both runs, diagnose, print the verdict, write the report."""
    from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
    from panto.identification.estimation.global_fit import GlobalFitOptions
    from panto.identification.diagnosis.report import write_report

    candidates, role_values = _candidates(args.candidates), _role_values(args.roles)
    options = structure_options(args.model, _pairs(args.option, "--option"))
    train = _load(args.train, args, validation=False)
    validation = _load(args.validate, args, validation=True)
    if args.free:
        options["free"] = tuple(args.free)
    say(f"diagnose {args.model}: training {args.train} ({len(train)} samples at "
        f"{1 / train.sample_period:g} Hz), validation {args.validate} ({len(validation)} samples)")
    _check_options(args.model, train, options)
    search = DiagnosisOptions(candidates=candidates, roles=_roles(role_values, train),
                              max_effects=args.max_effects, folds=args.folds,
                              workers=args.workers, **({"max_evaluations": args.max_evaluations}
                                                       if args.max_evaluations else {}),
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


def structure_options(model: str, pairs: dict[str, str]) -> dict[str, Any]:
    """The ``--option`` texts `pairs` as values of the kinds structure `model` takes.

    The options are the keyword arguments of the structure's constructor (those the data does
    not set), their kinds from its annotations (``bool | None``: ``true``, ``false`` or
    ``none``). An unknown key, an option not settable from the command line (a mapping) or a
    value of the wrong kind is refused (``ValueError``, bad input: the option does not fit the
    structure) naming the key, the value and what is allowed.
    """
    if not pairs:
        return {}
    settable = settable_options(model)
    out = {}
    for key, text in pairs.items():
        if key not in settable:
            allowed = ", ".join(f"{k} ({_describe(a) or 'not settable here'})"
                                for k, a in settable.items()) or "none"
            raise ValueError(f"--option: structure {model!r} takes no option {key!r}; its "
                             f"options are {allowed}")
        out[key] = _convert(model, key, text, settable[key])
    return out


def settable_options(model: str) -> dict[str, str]:
    """Option name -> annotation of structure `model` (its builder's keyword arguments, and
    where the builder passes ``**options`` on, its class constructor's; not ``outputs``, which
    the data sets). Empty for a structure the diagnosis cannot build (the build says why)."""
    import importlib
    import inspect

    from panto.identification.structures.registry import structure_info

    entry = structure_info(model)
    arguments = entry.match(model) or {}
    if entry.build is None:
        return {}
    build = getattr(importlib.import_module(f"panto.identification.structures.{entry.module}"),
                    entry.build)
    signature = inspect.signature(build)
    found = {}
    for parameter in list(signature.parameters.values())[1:]:
        if parameter.kind is parameter.VAR_KEYWORD:
            made = signature.return_annotation
            made = build.__globals__.get(made) if isinstance(made, str) else made
            if made is not None:
                found.update(_keywords(inspect.signature(made.__init__), {"self", "outputs"}))
        elif parameter.name not in arguments:
            found.update(_keywords(inspect.Signature([parameter]), set()))
    return {k: v for k, v in found.items() if k not in arguments}


def _keywords(signature, skipped: set[str]) -> dict[str, str]:
    import inspect

    return {p.name: p.annotation if isinstance(p.annotation, str)
            else inspect.formatannotation(p.annotation) for p in signature.parameters.values()
            if p.name not in skipped and p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}


def _kinds(annotation: str) -> set[str] | None:
    """The scalar kinds of an annotation (``"bool | None"`` -> {bool, None}); None when it is not
    a union of scalars (a mapping, a sequence)."""
    kinds = {part.strip() for part in annotation.replace("Optional[", "None|").strip("]")
             .split("|")}
    return kinds if kinds <= set(_KINDS) else None


def _describe(annotation: str) -> str:
    kinds = _kinds(annotation)
    names = [_KINDS[k] for k in _KINDS if k in (kinds or ())]
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else "".join(names)


def _convert(model: str, key: str, text: str, annotation: str) -> Any:
    """`text` as the first kind of `annotation` it reads as (module notes)."""
    import math

    kinds = _kinds(annotation)
    if kinds is None:
        raise ValueError(f"--option {key}: structure {model!r} takes a {annotation} for it, "
                         "which the command line does not set")
    lowered = text.lower()
    if "None" in kinds and lowered == "none":
        return None
    if "bool" in kinds and lowered in ("true", "false", "yes", "no"):
        return lowered in ("true", "yes")
    for kind, name in ((int, "int"), (float, "float")):
        if name in kinds:
            try:
                value = kind(text)
            except ValueError:
                continue
            if math.isfinite(value):
                return value
    if "str" in kinds:
        return text
    raise ValueError(f"--option {key}={text}: structure {model!r} takes "
                     f"{_describe(annotation)} for {key}")


def _check_options(model: str, train, options: dict[str, Any]) -> None:
    """Build the nominal once with the ``--option`` values: a value the structure refuses (out
    of its range) is refused by name before the diagnosis starts."""
    from panto.identification.structures.registry import build_structure

    given = {k: v for k, v in options.items() if k != "free"}
    if not given:
        return
    try:
        build_structure(model, train, given)
    except TypeError as error:
        if "keyword argument" not in str(error):
            raise
        wrong = str(error).rsplit(" ", 1)[-1]
        raise ValueError(f"--option: structure {model!r} takes no option {wrong} ({error})"
                         ) from None
    except ValueError as error:
        build_structure(model, train, {})  # fails alike without the options: the data's fault
        shown = ", ".join(f"{k}={v}" for k, v in given.items())
        raise ValueError(f"--option {shown}: {error}") from None


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
    p.add_argument("--roles", help="which signal plays which part: ROLE=SIGNAL,... with ROLE "
                   "among " + ", ".join(ROLES) + " (actuators=a+b)")
    p.add_argument("--candidates", nargs="*", help="subset of the effect vocabulary")
    p.add_argument("--free", nargs="*", help="free parameters of the nominal")
    p.add_argument("--option", nargs="*", help="structure option KEY=VALUE (e.g. centre=true, "
                   "cutoff=0.2, input_delay=1)")
    p.add_argument("--max-effects", type=non_negative_int, default=3,
                   help="most effects added one after another (default 3)")
    p.add_argument("--folds", type=positive_int, default=4,
                   help="blocks of the validation run for the fold statistics (default 4)")
    p.add_argument("--max-evaluations", type=positive_int,
                   help="most model simulations per least-squares fit (default 400)")
    p.add_argument("--workers", type=positive_int,
                   help="processes for a round's candidate refits (default: the CPUs "
                        "available; 1: in this process)")
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
