"""``panto identify``: fit a model structure to a rig run (thesis chapter 4).

``panto identify RUN --model physical-linear [--validate RUN] [--free a b] [--fix k_ph=50000]
[--method lm|nsga2] [--multistart N] [--initial auto|defaults|data] [--no-adequacy] [--workers N]
[--out DIR] [--json FILE] [--rate 50] [--start S --stop S] [--keep-unidentifiable]`` prints the progress, a table (parameter, value,
unit, std, 95 % interval, nominal, verdict) and the fits (with ``--correlations`` the correlation
matrix of the estimates, also in the files), and writes the parameter file, the result
JSON, its markdown summary and the plot into ``--out``. With ``lm``, parameters the run cannot
pin are fixed at their prior and the rest refitted, unless ``--keep-unidentifiable``; with
``--initial data`` (the default, ``auto``, for the structures of :data:`DATA_STARTS`) the fit is
:func:`~panto.identification.estimation.global_fit.fit_global` (also from data-driven starts), its
verdict printed and kept in ``result.json`` (``global_fit``), and the fit is set beside a black box
of the structure's order (:mod:`~panto.identification.structures.adequacy`; ``--no-adequacy``
skips it).

The data are a rig run (the rig mapping eta, p -> F_c, y_cb when no columns are named) or any
table with ``--inputs NAME=COLUMN ... --outputs NAME=COLUMN ...`` (``--sample-rate``,
``--train-samples``/``--validate-samples``: the options of ``panto diagnose``,
:mod:`panto.data_options`), e.g. ``panto identify train.csv --model two-mass --inputs eta=height
p=pressure --outputs F_c=force``.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Callable

from panto.console import progress, say, write_json
from panto.data_options import (add_data_options, load_data, non_negative_float, non_negative_int,
                                positive_int)


#: Structures whose fit can start from the data (``--initial data``: they have a linear system).
DATA_STARTS = ("two-mass", "three-mass", "physical-linear")


def _fixed(items: list[str] | None) -> dict[str, float]:
    fixed = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            fixed[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise ValueError(f"--fix {item!r}: expected NAME=VALUE, e.g. k_ph=50000")
    return fixed


def _executor(workers: int):
    if workers <= 1:
        return None
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(max_workers=workers)


def run_identify(args: argparse.Namespace) -> int:
    """Load the runs, fit, print, write."""
    from panto.identification.structures.registry import identifier, parameter_set
    from panto.identification.estimation.reporting import write_identification

    def load(path: str, validation: bool):
        return load_data(path, args, validation=validation, rig_mapping=True, start=args.start,
                         stop=args.stop, cross_bar=args.cross_bar,
                         position_latency=args.position_latency,
                         rig_outputs=("F_c", "y_cb", "xi") if args.model == "collector-head"
                         else ("F_c", "y_cb"))

    data = load(args.dataset, False)
    validation = load(args.validate, True) if args.validate else None
    options = {"fixed": _fixed(args.fix), "method": args.method}
    if args.free:
        options["free"] = args.free
    if args.method == "lm":
        options.update(multistart=args.multistart, max_evaluations=args.max_evaluations)
        initial = args.initial if args.initial != "auto" else \
            "data" if args.model in DATA_STARTS and not args.multistart else "defaults"
        if initial == "data" and args.model not in DATA_STARTS:
            say(f"--initial data: {args.model} has no data-driven start (those: "
                f"{', '.join(DATA_STARTS)}); fitting from the defaults")
        elif initial == "data":
            from panto.identification.estimation.global_fit import GlobalFitOptions

            options["global_fit"] = GlobalFitOptions()
        if args.model in DATA_STARTS and args.adequacy:
            options["adequacy"] = True
        if not args.model.startswith(("blackbox-", "collector-head")) and \
                "global_fit" not in options:
            options["fix_unidentifiable"] = not args.keep_unidentifiable
        if args.multistart:
            import numpy as np

            options["rng"] = np.random.default_rng(args.seed)
    say(f"identify {args.model} on {args.dataset}: {len(data)} samples at "
        f"{1.0 / data.sample_period:g} Hz")
    executor = _executor(args.workers)
    try:
        result = identifier(args.model).identify(data, executor=executor, progress=progress,
                                                 **options)
    finally:
        if executor is not None:
            executor.shutdown()
    _print_result(result, validation)
    if args.correlations:
        from panto.identification.estimation.correlations import (correlation_lines,
                                                                  parameter_correlations)

        for line in correlation_lines(parameter_correlations(result)):
            say(line)
    if "global_fit" in result.details:
        say(result.details["global_fit"]["verdict"])
    if "adequacy" in result.details:
        say("adequacy: " + result.details["adequacy"]["message"])
    if args.out and args.model == "collector-head":
        _write_collector_head(data, Path(args.out))
    elif args.out:
        nominal = _nominal(args.model)
        paths = write_identification(result, args.out, data=data, validation=validation,
                                     nominal=nominal, parameter_set=parameter_set(args.model),
                                     correlations=args.correlations)
        for path in paths.values():
            say(f"wrote {path}")
    if args.json:
        from panto.identification.estimation.reporting import result_summary

        summary = result_summary(result, data=data, validation=validation,
                                 correlations=args.correlations)
        write_json(args.json, summary, default=str)
    return 0 if result.success else 1


def _write_collector_head(data, folder: Path) -> None:
    """The head's PT2 fits (eqs. 4.15/4.16) as JSON and their Bode plot against the H1 estimate."""
    from panto.identification.structures.collector_head import identify_collector_head
    from panto.identification.structures.plots import plot_collector_head

    folder.mkdir(parents=True, exist_ok=True)
    head = identify_collector_head(data)
    (folder / "result.json").write_text(json.dumps(head.to_dict(), indent=2, default=str) + "\n")
    plot_collector_head(head, folder / "bode.png")
    say(f"wrote {folder / 'result.json'}")
    say(f"wrote {folder / 'bode.png'}")


def _nominal(model: str) -> dict[str, float] | None:
    from panto.identification.structures.registry import parameter_set

    if parameter_set(model) == "Pantograph":
        from panto.identification.structures.physical import PhysicalLinear

        return PhysicalLinear().nominal()
    return None


def _print_result(result, validation) -> None:
    nominal = _nominal(result.structure) or {}
    if result.estimates:
        say(f"{'parameter':>10} {'value':>12} {'unit':<10} {'std':>10} {'95 % interval':>24} "
            f"{'nominal':>12}  verdict")
    else:
        say(f"{'parameter':>10} {'value':>12} {'std':>10} {'nominal':>12}")
    for name, e in result.estimates.items():
        interval = f"[{e.interval_95[0]:.4g}, {e.interval_95[1]:.4g}]" if not e.at_bound and \
            not e.fixed else ""
        verdict = e.status if e.fixed else e.verdict if not e.at_bound else \
            f"{e.verdict}: {e.status}"
        say(f"{name:>10} {e.value:12.5g} {e.unit:<10} {e.std:10.3g} {interval:>24} "
            f"{nominal.get(name, math.nan):12.5g}  {verdict}")
    for name in [] if result.estimates else result.free:
        value, std = result.parameters[name], result.std.get(name, math.nan)
        say(f"{name:>10} {value:12.5g} {std:10.3g} {nominal.get(name, math.nan):12.5g}")
    say("fit on training: " + ", ".join(f"{k} {v:.1f} %" for k, v in result.fit.items()))
    if validation is not None:
        fits = result.fit_on(validation, [o for o in result.fit if o in validation.output_names])
        say("fit on validation: " + ", ".join(f"{k} {v:.1f} %" for k, v in fits.items()))
    weak = (result.details.get("identifiability") or {}).get("not_identifiable") or {}
    for name, why in {**weak, **result.details.get("fixed_at_prior", {})}.items():
        fixed = " (fixed at prior)" if name in result.details.get("fixed_at_prior", {}) else ""
        say(f"not identifiable{fixed}: {name}: {why}")
    for name, e in result.estimates.items():
        if e.at_bound:
            say(f"at {e.at_bound} bound: {name}: {e.reason}")
    say(f"{'' if result.success else 'FAILED: '}{result.message} "
        f"({result.n_evaluations} evaluations, {result.wall_time:.1f} s)")


def register(add: Callable[..., argparse.ArgumentParser]) -> None:
    """Declare ``panto identify``."""
    p = add("identify", run_identify, "fit a model structure to a rig run (thesis chapter 4)")
    p.add_argument("dataset", help="training data: run folder, or a table (.csv, .parquet, "
                   ".mat, .h5) with --inputs/--outputs")
    p.add_argument("--model", default="physical-linear",
                   help="structure: physical, physical-linear, two-mass, ... (default "
                        "physical-linear)")
    p.add_argument("--validate", help="validation data (run folder or table, same columns)")
    p.add_argument("--free", nargs="+", help="parameters to estimate (default: the structure's)")
    p.add_argument("--fix", nargs="+", metavar="NAME=VALUE", help="parameters held fixed")
    p.add_argument("--method", default="lm", choices=("lm", "nsga2"),
                   help="Levenberg-Marquardt (lm, default) or the NSGA-II Pareto front (nsga2)")
    p.add_argument("--multistart", type=non_negative_int, default=0,
                   help="extra LM runs from random starts")
    p.add_argument("--seed", type=non_negative_int, default=None,
                   help="seed of the multistart points")
    p.add_argument("--max-evaluations", type=positive_int, default=2000,
                   help="budget of model evaluations of the fit (default 2000)")
    p.add_argument("--keep-unidentifiable", action="store_true",
                   help="lm: leave parameters the run cannot pin free (default: fix them at their "
                        "prior and refit, reported as 'fixed at prior')")
    p.add_argument("--initial", default="auto", choices=("auto", "defaults", "data"),
                   help="lm: where the fit starts: the structure's defaults, or also from the "
                        "data's frequency response and perturbations (fit_global; "
                        f"{', '.join(DATA_STARTS)}), which prints whether the starts agree on "
                        "a global optimum and keeps parameters the run cannot pin free; auto "
                        "(default): data for those structures, defaults for the others")
    p.add_argument("--no-adequacy", dest="adequacy", action="store_false",
                   help=f"lm, {', '.join(DATA_STARTS)}: skip the comparison with a black box of "
                        "the structure's order (adequacy: did the fit converge, can the "
                        "structure express the data's linear dynamics)")
    p.add_argument("--workers", type=positive_int, default=1, help="processes for the evaluations")
    p.add_argument("--correlations", action="store_true",
                   help="also print the correlation matrix of the estimates and add it to the "
                        "--out reports and --json (parameters at a bound or fixed left out, "
                        "named)")
    p.add_argument("--out", help="folder for parameters.json, result.json and fit.png")
    p.add_argument("--json", help="also write the result summary as JSON")
    add_data_options(p)
    p.add_argument("--start", type=float, help="start of the time window [s]")
    p.add_argument("--stop", type=float, help="end of the time window [s]")
    p.add_argument("--cross-bar", default="laser", choices=("laser", "video"),
                   help="rig runs: the measurement that gives y_cb (default laser)")
    p.add_argument("--position-latency", type=non_negative_float,
                   help="how late the drive reports the slider position [s] (default: the run's "
                        "recorded rig set-up, else 0); physical structures also take "
                        "--fix eta_delay=SECONDS or --free ... eta_delay")
