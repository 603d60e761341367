"""``panto compare`` and ``panto sensitivity`` (thesis section 4.8 and Fig. 4.9).

* ``panto compare TRAIN VALIDATION [--structures ...] [--workers N] [--out FOLDER] [--json FILE]``
  fits every model structure on the training run, validates it on the validation run and prints
  the thesis' table; ``--out`` writes the table (Markdown, CSV, JSON), the bar chart of the fits
  and one validation plot per structure. Rig runs use the rig mapping; any table takes the data
  options of ``panto diagnose`` (``--inputs``/``--outputs NAME=COLUMN``, ``--sample-rate``,
  ``--train-samples``/``--validate-samples``, ``--rate``; :mod:`panto.data_options`).
* ``panto sensitivity [--parameters FILE] [--eta 2.0] [--p 4.0] [--out PNG] [--json FILE]``:
  eigenvalues of the linearised pantograph with each Table 4.1 parameter scaled by 0.9 and 1.1,
  ranked by influence.
"""
from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from pathlib import Path
from typing import Callable

from panto.console import progress, say, write_json
from panto.data_options import (add_data_options, load_data, non_negative_float, positive_float,
                                positive_int)


def run_compare(args: argparse.Namespace) -> int:
    """Fit the structures on TRAIN, validate on VALIDATION, print and write the table."""
    from panto.identification.estimation.comparison import compare_structures
    from panto.identification.estimation.plots import plot_comparison, plot_validation
    from panto.identification.structures.registry import comparison_identifiers

    train = load_data(args.train, args, rig_mapping=True)
    validation = load_data(args.validation, args, validation=True, rig_mapping=True)
    say(f"training {args.train}: {len(train)} samples at {1 / train.sample_period:.0f} Hz; "
        f"validation {args.validation}: {len(validation)} samples")
    pool = ProcessPoolExecutor(args.workers) if args.workers and args.workers > 1 \
        else nullcontext(None)
    with pool as executor:
        table = compare_structures(train, validation,
                                   structures=comparison_identifiers(args.structures or None),
                                   executor=executor, progress=progress)
    say(table.to_markdown())
    if args.out:
        folder = Path(args.out)
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "comparison.md").write_text(table.to_markdown() + "\n")
        table.to_csv(folder / "comparison.csv")
        table.write_json(folder / "comparison.json")
        plot_comparison(table, folder / "comparison.png")
        plots = plot_validation(table, validation, folder)
        _save_parameters(table, folder)
        say(f"wrote {folder}/comparison.(md|csv|json|png) and {len(plots)} validation plots")
    if args.json:
        write_json(args.json, table.to_dict())
    return 0 if any(row.result is not None for row in table.rows) else 1


def _save_parameters(table, folder: Path) -> None:
    """The physical structures' identified parameters as files the FMUs accept."""
    from panto.fmu_src.models import default_parameters
    from panto.identification.structures.registry import parameter_set

    names = set(default_parameters("Pantograph").names)
    for row in table.rows:
        if row.result is not None and parameter_set(row.structure) == "Pantograph":
            values = {k: v for k, v in row.result.parameters.items() if k in names}
            default_parameters("Pantograph").with_values(values).save(
                folder / f"parameters_{row.structure}.json")


def run_sensitivity(args: argparse.Namespace) -> int:
    """Eigenvalues of the linearised model with each parameter scaled (thesis Fig. 4.9)."""
    from panto.fmu_src.models import default_parameters
    from panto.fmu_src.parameters import ParameterSet
    from panto.identification.structures.plots import plot_eigenvalue_sensitivity
    from panto.identification.structures.sensitivity import TABLE_4_1, eigenvalue_sensitivity

    # The file is read against the pantograph's specs (units, bounds); whether the linkage
    # closes is checked by the linearisation itself (a clear error if it cannot).
    parameters = ParameterSet.load(args.parameters, default_parameters("Pantograph").specs,
                                   "Pantograph") if args.parameters else None
    result = eigenvalue_sensitivity(parameters, eta=args.eta, p=args.p,
                                    names=args.names or TABLE_4_1,
                                    factors=tuple(args.factors))
    say("modes [Hz]: " + ", ".join(f"{f:.3f}" for f in result.natural_frequencies_hz))
    say(result.to_markdown())
    for shift in result.shifts:
        if shift.message:
            say(f"{shift.name}: {shift.message}")
    if args.out:
        plot_eigenvalue_sensitivity(result, args.out)
        say(f"wrote {args.out}")
    if args.json:
        write_json(args.json, result.to_dict())
    return 0


def register(add: Callable) -> None:
    """Declare ``compare`` and ``sensitivity`` with ``add(name, handler, help)``."""
    p = add("compare", run_compare, "fit every model structure on a training run, validate on "
            "a validation run: the thesis' table (section 4.8)")
    p.add_argument("train", help="training run folder or table (APRBS)")
    p.add_argument("validation", help="validation run folder or table (ramps)")
    p.add_argument("--structures", nargs="+", help="structure names (default: all in the "
                   "comparison, e.g. physical-linear three-mass blackbox-4)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes evaluating populations / Jacobians in parallel (default 1)")
    add_data_options(p)
    p.add_argument("--out", help="folder for the table (md, csv, json), plots, parameter files")
    p.add_argument("--json", help="write the table as JSON to this file")

    p = add("sensitivity", run_sensitivity, "eigenvalues of the linearised pantograph with "
            "each parameter scaled by 0.9 and 1.1, ranked by influence (thesis Fig. 4.9)")
    p.add_argument("--parameters", help="parameter file (JSON), e.g. an identified set")
    p.add_argument("--eta", type=float, default=2.0, help="wire height [m] (2.0)")
    p.add_argument("--p", type=non_negative_float, default=4.0, help="bellow pressure [bar] (4.0)")
    p.add_argument("--names", nargs="+", help="parameters to scale (default Table 4.1's 13)")
    p.add_argument("--factors", type=positive_float, nargs="+", default=[0.9, 1.1],
                   help="multipliers (default 0.9 1.1)")
    p.add_argument("--out", help="PNG: complex plane and ranking")
    p.add_argument("--json", help="write the eigenvalues and ranking as JSON")
