"""``panto rig``: the rig sidecar and the virtual test bed (thesis chapter 3).

``panto rig run PROFILE`` plays a profile on the virtual test bed (default) or on a real rig
(``--interface``/``--channel`` for the CAN bus and ``--io MODULE:FACTORY`` for the analogue I/O);
``panto rig emulate`` serves the emulated drive and plant on a CAN bus in real time;
``panto rig profile`` renders a profile to a plot and CSV before it is run;
``panto rig check`` checks a dataset against the schema and summarises it.
"""
from __future__ import annotations

import argparse
import importlib
import json
from dataclasses import fields, replace
from pathlib import Path
from typing import Callable

from panto.console import progress, say
from panto.data_options import (UsageError, non_negative_float, non_negative_int, positive_float,
                                positive_int)


def _imperfections(text: str):
    from panto.rig.imperfections import RigImperfections

    if text == "none":
        return RigImperfections.none()
    if text == "default":
        return RigImperfections()
    path = Path(text)
    try:
        values = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise ValueError(f"--imperfections {text}: not 'none', 'default' or a readable JSON "
                         f"file ({error})") from None
    if not isinstance(values, dict):
        raise ValueError(f"--imperfections {text}: expected a JSON object of imperfection names")
    known = {f.name for f in fields(RigImperfections)}
    unknown = sorted(set(values) - known - {"provenance"})
    if unknown:
        raise ValueError(f"--imperfections {text}: unknown imperfection(s) {unknown}; known: "
                         f"{', '.join(sorted(known))}")
    try:
        return RigImperfections.from_dict(values)
    except TypeError as error:
        raise ValueError(f"--imperfections {text}: {error}") from None


def _pantograph_fmu(args: argparse.Namespace) -> Path:
    if args.fmu:
        return Path(args.fmu)
    from panto.build_fmu.project import project_fmu

    return project_fmu("Pantograph", progress=progress)


def run_rig_run(args: argparse.Namespace) -> int:
    """Play a profile and record the run."""
    from panto.rig.profiles import load_profile
    from panto.rig.recorder import new_run_folder

    profile = load_profile(args.profile)
    if args.duration is not None:
        from panto.rig.profiles import check_profile

        profile = replace(profile, duration=args.duration)
        check_profile(profile, source=f"{args.profile} with --duration {args.duration:g}")
    imperfections = _imperfections(args.imperfections)  # refused before a folder is made
    fmu = None if args.interface else _pantograph_fmu(args)
    if args.interface and not args.io:
        raise UsageError("a real rig needs --io MODULE:FACTORY: a function returning the rig's "
                         "analogue I/O (an object with read_sensors(now), write_valve_voltage(v), "
                         "write_led(bit); see panto.rig.session.RigIO)")
    existed = bool(args.folder) and Path(args.folder).exists()
    folder = Path(args.folder) if args.folder else new_run_folder(args.out)
    try:
        return _record(args, profile, folder, imperfections, fmu)
    except BaseException:
        if not existed and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()  # nothing was recorded: leave no empty run folder
        raise


def _record(args: argparse.Namespace, profile, folder: Path, imperfections, fmu) -> int:
    """Run `profile` into `folder` (real rig, real time or lock step); print the outcome."""
    from panto.rig.session import RunOptions

    options = RunOptions(formats=tuple(args.formats), notes=args.notes or "",
                         rig_setup={key: value for key, value in
                                    (("motor_zero_height", args.motor_zero_height),
                                     ("position_latency", args.position_latency))
                                    if value is not None})
    if args.interface:
        result = _run_on_rig(args, profile, folder, options)
    elif args.realtime:
        from panto.rig.realtime import run_virtual_profile_realtime

        result = run_virtual_profile_realtime(
            profile, fmu_path=fmu, folder=folder, imperfections=imperfections, seed=args.seed,
            options=options, progress=progress)
    else:
        from panto.rig.virtual import run_virtual_profile

        result = run_virtual_profile(
            profile, fmu_path=fmu, folder=folder, imperfections=imperfections, seed=args.seed,
            options=options, progress=progress)
    say(f"{result.samples} samples, {result.late_cycles} late cycles; status: {result.status}")
    return 0 if result.success else 1


def _run_on_rig(args: argparse.Namespace, profile, folder: Path, options):
    """The real rig: the CAN interface by configuration, the analogue I/O from a user factory."""
    from panto.rig.clock import RealClock
    from panto.rig.drive import LinearMotorDriver
    from panto.rig.session import run_profile

    module_name, _, factory_name = args.io.partition(":")
    try:
        factory = getattr(importlib.import_module(module_name), factory_name)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"--io {args.io}: cannot load the I/O factory ({error})") from None
    clock = RealClock()
    with LinearMotorDriver.open(args.interface, args.channel, clock=clock,
                                node_id=args.node_id,
                                position_limits=(profile.limits.motor_min,
                                                 profile.limits.motor_max)) as driver:
        return run_profile(profile, driver=driver, io=factory(), clock=clock, folder=folder,
                           options=options, progress=progress)


def run_rig_emulate(args: argparse.Namespace) -> int:
    """Serve the emulated drive (with the plant behind it) on a CAN bus in real time."""
    from panto.rig.realtime import serve_emulator

    serve_emulator({"interface": args.interface, "channel": args.channel},
                   fmu_path=_pantograph_fmu(args), duration=args.duration, progress=progress)
    return 0


def run_rig_profile(args: argparse.Namespace) -> int:
    """Render a profile (demand, conditioned command, pressure, LED) to CSV and a plot."""
    from panto.rig.profile_preview import preview_profile

    written = preview_profile(args.profile, out=Path(args.out))
    for path in written:
        say(f"wrote {path}")
    return 0


def run_rig_check(args: argparse.Namespace) -> int:
    """Check a dataset against the schema; print its channels and status."""
    from panto.rig.dataset import REQUIRED_CHANNELS, check_plausible, read_dataset

    data = read_dataset(args.dataset, required=() if args.any_channels else REQUIRED_CHANNELS)
    check_plausible(data, args.dataset)
    say(f"{args.dataset}: {len(data)} samples at {data.metadata.sample_rate:g} Hz, "
        f"{data.time[-1] - data.time[0]:.3f} s, source {data.metadata.source}, "
        f"status {data.metadata.status}")
    for name in data.names:
        values = data[name]
        say(f"  {name:>16} [{data.units[name]}]  min {values.min():.6g}  max {values.max():.6g}")
    for warning in data.warnings:
        say(f"  warning: {warning}")
    return 0


def register(add: Callable) -> None:
    """Declare ``panto rig`` with its sub-subcommands."""
    rig = add("rig", _dispatch, "rig sidecar: run a profile, emulate the rig, preview, check")
    sub = rig.add_subparsers(dest="rig_command", required=True,
                             help="what to do; 'panto rig WHAT --help' for its options")

    p = sub.add_parser("run", help="play a profile and record the run (virtual test bed unless "
                                   "--interface is given)")
    p.set_defaults(rig_handler=run_rig_run)
    p.add_argument("profile", help="profile file (JSON), e.g. rig/profiles/aprbs_training.json")
    p.add_argument("--out", default="runs", help="folder of numbered runs (default: runs)")
    p.add_argument("--folder", help="exact run folder (refused if it holds a run)")
    p.add_argument("--duration", type=positive_float, help="override the profile's duration [s]")
    p.add_argument("--formats", nargs="*", default=["parquet", "mat"], choices=("parquet", "mat"),
                   help="copies written beside the incremental CSV")
    p.add_argument("--notes", help="free text stored in the run's metadata")
    p.add_argument("--fmu", help="pantograph FMU of the virtual test bed (default: built)")
    p.add_argument("--imperfections", default="default",
                   help="'default' (the rig as the thesis describes it), 'none', or a JSON file")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of the emulated sensor noise")
    p.add_argument("--realtime", action="store_true",
                   help="emulate against the wall clock instead of in lock step")
    p.add_argument("--interface", help="python-can interface of a real rig (e.g. socketcan, pcan)")
    p.add_argument("--channel", help="CAN channel of a real rig (e.g. can0)")
    p.add_argument("--node-id", type=positive_int, default=63, help="the drive's CANopen node id")
    p.add_argument("--motor-zero-height", type=float,
                   help="height [m] of the bar at slider position 0, recorded in the run's "
                        "metadata for identification (virtual test bed: its own, 2.0 m)")
    p.add_argument("--position-latency", type=non_negative_float,
                   help="how late the drive's reported slider position is [s], recorded for "
                        "identification (virtual test bed: 0.005)")
    p.add_argument("--io", help="MODULE:FACTORY returning the real rig's analogue I/O")

    p = sub.add_parser("emulate", help="serve the emulated drive and plant on a CAN bus")
    p.set_defaults(rig_handler=run_rig_emulate)
    p.add_argument("--interface", default="udp_multicast",
                   help="python-can interface shared with the master (default udp_multicast)")
    p.add_argument("--channel", default=None, help="CAN channel (interface default if omitted)")
    p.add_argument("--fmu", help="pantograph FMU (default: built)")
    p.add_argument("--duration", type=positive_float, help="stop after this many seconds")

    p = sub.add_parser("profile", help="render a profile to CSV and a plot before running it")
    p.set_defaults(rig_handler=run_rig_profile)
    p.add_argument("profile", help="profile file (JSON)")
    p.add_argument("--out", default="profile_preview", help="output folder")

    p = sub.add_parser("check", help="check a dataset against the schema and summarise it")
    p.set_defaults(rig_handler=run_rig_check)
    p.add_argument("dataset", help="run folder or .csv/.parquet/.mat file")
    p.add_argument("--any-channels", action="store_true",
                   help="do not require the rig's standard channels")


def _dispatch(args: argparse.Namespace) -> int:
    return args.rig_handler(args)
