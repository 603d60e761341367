"""``panto cosim``: pantograph FMU against a finite-difference catenary.

One subcommand with four jobs:

* a run (default): ``panto cosim --line en50318-2002 --speed 250 --pantograph en50318-2002
  --out DIR --json FILE`` prints the EN 50318 statistics, writes the time series (CSV + JSON
  metadata), the force and uplift plots and, with ``--json``, the statistics beside the settings;
  ``--fmu PATH --height-input NAME --force-output NAME`` runs a user's FMU instead;
* ``--validate-en50318 --out DIR``: the EN 50318:2002 validation report;
* ``--rig-sequence FILE``: the thesis' periodic rig excitation (Fig. 3.4);
* ``--build-catenary-fmu DIR``: the catenary as a Co-Simulation FMU (pythonfmu).
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable

from panto.console import progress, say, write_json
from panto.data_options import non_negative_float, positive_float, positive_int


def _setup(args: argparse.Namespace):
    from panto.catenary_cosim.pantographs import pantograph_setup, user_pantograph

    if args.fmu and not args.pantograph:
        _check_variables(args)
        return user_pantograph(args.fmu, height_input=args.height_input,
                               force_output=args.force_output, head_output=args.head_output,
                               height_offset=args.height_offset)
    setup = pantograph_setup(args.pantograph or "en50318-2002", pressure_bar=args.pressure)
    return setup.with_fmu(args.fmu) if args.fmu else setup


def _check_variables(args: argparse.Namespace) -> None:
    """Before any work: a user FMU has the input and outputs named by the options."""
    from fmpy import read_model_description

    from panto.build_fmu.simulate import check_names

    description = read_model_description(args.fmu)
    names = {role: [v.name for v in description.modelVariables if v.causality == role]
             for role in ("input", "output")}
    check_names([args.height_input], names["input"], "input", description.modelName)
    check_names([n for n in (args.force_output, args.head_output) if n], names["output"],
                "output", description.modelName)


def _print_statistics(statistics: dict[str, float]) -> None:
    from panto.catenary_cosim.validation import LABELS

    for key, value in statistics.items():
        say(f"  {LABELS[key]:<32} {value:10.2f}")


def run_cosim(args: argparse.Namespace) -> int:
    """Dispatch to the job asked for (module notes)."""
    if args.build_catenary_fmu:
        from panto.catenary_cosim.catenary_fmu import build_catenary_fmu

        say(f"wrote {build_catenary_fmu(args.build_catenary_fmu)} (needs Python with the "
            "panto package on the importing side)")
        return 0
    if args.rig_sequence:
        from panto.catenary_cosim.rig_sequence import make_rig_sequence

        path = make_rig_sequence(args.rig_sequence, line=args.line or "thesis-60m",
                                 speed_kmh=args.speed or 300.0,
                                 pantograph=_setup(args) if args.pantograph or args.fmu
                                 else None, fmu_cache=args.fmu_cache, progress=progress)
        say(f"wrote {path} and {path.name}.json")
        return 0
    if args.validate_en50318:
        return _validate(args)
    return _run(args)


def _validate(args: argparse.Namespace) -> int:
    from panto.catenary_cosim.validation import validate_en50318

    if not args.out:
        raise ValueError("--validate-en50318 needs --out DIR")
    report = validate_en50318(args.out, time_step=args.time_step,
                              element_length=args.element_length or 0.25,
                              with_sensitivity=not args.no_sensitivity,
                              fmu_cache=args.fmu_cache, progress=progress)
    say(report.markdown.read_text().split("## ")[0])
    return 0 if report.all_inside else 1


def _run(args: argparse.Namespace) -> int:
    from panto.catenary_cosim.master import cosimulate

    if args.speed is None:
        raise ValueError("give the running speed with --speed KMH")
    result = cosimulate(args.line or "en50318-2002", _setup(args), speed_kmh=args.speed,
                        time_step=args.time_step, communication_step=args.communication_step,
                        element_length=args.element_length, damping=not args.no_damping,
                        interface=args.interface, fmu_cache=args.fmu_cache, progress=progress)
    statistics = result.statistics().to_dict()
    say(f"{result.message}; {result.timing['simulated_seconds_per_wall_second']:.2f} "
        "simulated s per wall s")
    say("EN 50318 statistics over the analysed section:")
    _print_statistics(statistics)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        stem = f"{result.settings['line']}_{args.speed:g}kmh"
        say(f"wrote {result.to_csv(out / f'{stem}.csv', every=args.csv_every)}")
        for path in result.save_plots(out, stem=stem):
            say(f"wrote {path}")
    if args.json:
        document = {**statistics, "settings": result.settings, "counters": result.counters,
                    "timing": result.timing, "statistics_details": result.statistics().details(),
                    "message": result.message}
        write_json(args.json, document, default=str)
    return 0


def register(add: Callable) -> None:
    """Declare this package's subcommands with ``add(name, handler, help)``."""
    p = add("cosim", run_cosim, "co-simulate a pantograph FMU against an overhead line "
            "(EN 50318 statistics), validate, make the rig sequence or the catenary FMU")
    p.add_argument("--line", help="line name (en50318-2002, benchmark-2015, thesis-60m) or a "
                   "line file (JSON); default en50318-2002 (thesis-60m for --rig-sequence)")
    p.add_argument("--speed", type=float, help="running speed [km/h]")
    p.add_argument("--pantograph", help="en50318-2002 (default), benchmark-2015, physical, "
                   "physical-linear")
    p.add_argument("--pressure", type=non_negative_float,
                   help="bellow pressure of the physical pantograph "
                   "[bar] (default 4)")
    p.add_argument("--fmu", help="a pantograph FMU file (yours, or a built project FMU)")
    p.add_argument("--height-input", default="eta", help="FMU input for the wire height")
    p.add_argument("--force-output", default="F_c", help="FMU output for the contact force")
    p.add_argument("--head-output", help="FMU output for the head height (optional)")
    p.add_argument("--height-offset", type=float, default=0.0,
                   help="added to the wire height [m] before it goes to your FMU")
    p.add_argument("--time-step", type=positive_float, default=5e-4,
                   help="catenary time step = default communication step [s] (5e-4)")
    p.add_argument("--communication-step", type=positive_float,
                   help="FMU communication step [s], a multiple of the time step")
    p.add_argument("--element-length", type=positive_float, help="catenary element length [m]")
    p.add_argument("--no-damping", action="store_true", help="switch the line's damping off")
    p.add_argument("--interface", choices=("CS", "ME"), default="CS",
                   help="drive the FMU by Co-Simulation (default) or Model Exchange (CVODE)")
    p.add_argument("--fmu-cache", help="folder for project FMUs built on demand")
    p.add_argument("--out", help="folder for the time series (CSV), plots (PNG), reports")
    p.add_argument("--csv-every", type=positive_int, default=1, help="write every n-th sample")
    p.add_argument("--json", help="write the statistics and the settings to this JSON file")
    p.add_argument("--validate-en50318", action="store_true",
                   help="run the EN 50318:2002 validation (with --out DIR)")
    p.add_argument("--no-sensitivity", action="store_true",
                   help="validation without the sensitivity study")
    p.add_argument("--rig-sequence", metavar="FILE",
                   help="write the periodic rig excitation (thesis Fig. 3.4) to FILE (CSV)")
    p.add_argument("--build-catenary-fmu", metavar="DIR",
                   help="build the catenary Co-Simulation FMU (pythonfmu) into DIR")
