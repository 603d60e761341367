"""``panto``: the command-line interface. Each subcommand is one small function in a table."""
from __future__ import annotations

import argparse
import importlib
import json
import logging
import sys
from pathlib import Path
from typing import Callable

from panto.console import say


def run_build_fmu(args: argparse.Namespace) -> int:
    """Build, validate and list the FMUs."""
    from panto.build_fmu.project import build_project_fmus

    built = build_project_fmus(args.out, names=args.models or _all_fmus(),
                               fmi_versions=args.fmi_version, progress=say)
    failed = [b for b in built if b.problems]
    for b in failed:
        say(f"INVALID {b.path}: " + "; ".join(b.problems))
    return 1 if failed else 0


def _all_fmus():
    from panto.fmu_src.models import FMU_NAMES

    return FMU_NAMES


def run_linearise(args: argparse.Namespace) -> int:
    """Static equilibrium and linearisation about an operating point."""
    from panto.fmu_src.models import Model, load_parameters

    params = load_parameters(args.parameters, args.model) if args.parameters else None
    model = Model(args.model, params)
    lin = model.linearise(args.eta, args.p)
    result = {
        "model": args.model, "eta": args.eta, "p": args.p,
        "equilibrium": dict(zip(lin.state_names, lin.x0.tolist())),
        "outputs": dict(zip(lin.output_names, lin.y0.tolist())),
        "eigenvalues": [[ev.real, ev.imag] for ev in lin.eigenvalues],
        "natural_frequencies_hz": lin.natural_frequencies_hz.tolist(),
        "A": lin.A.tolist(), "B": lin.B.tolist(), "C": lin.C.tolist(), "D": lin.D.tolist(),
    }
    for name, value in result["outputs"].items():
        say(f"{name:>6} = {value:.6g}")
    say("modes [Hz]: " + ", ".join(f"{f:.3f}" for f in lin.natural_frequencies_hz))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
        say(f"wrote {args.json}")
    return 0


def run_parameters(args: argparse.Namespace) -> int:
    """Write a model's default parameter file (values, units, bounds, provenance)."""
    from panto.fmu_src.models import default_parameters

    path = default_parameters(args.model).save(args.out)
    say(f"wrote {path}")
    return 0


def run_demo(args: argparse.Namespace) -> int:
    """The main job on the embedded defaults."""
    from panto.demo import run_demo as demo

    demo(Path(args.out), quick=args.quick, progress=say)
    return 0


def _parser() -> tuple[argparse.ArgumentParser, dict[str, Callable]]:
    parser = argparse.ArgumentParser(prog="panto", description=__doc__)
    parser.add_argument("-v", "--verbose", action="store_true", help="log details")
    sub = parser.add_subparsers(dest="command", required=True)
    handlers: dict[str, Callable] = {}

    def add(name: str, handler: Callable, help_text: str) -> argparse.ArgumentParser:
        handlers[name] = handler
        return sub.add_parser(name, help=help_text, description=help_text)

    p = add("build-fmu", run_build_fmu, "generate, compile, package and validate the FMUs")
    p.add_argument("--out", default="fmus", help="output folder (default: fmus)")
    p.add_argument("--models", nargs="*", help="subset, e.g. Pantograph TwoMass")
    p.add_argument("--fmi-version", type=int, nargs="+", choices=(2, 3), default=[2, 3])

    p = add("linearise", run_linearise, "equilibrium, eigenvalues and A, B, C, D at (eta, p)")
    p.add_argument("--model", default="Pantograph", choices=("Pantograph", "TwoMass", "ThreeMass"))
    p.add_argument("--eta", type=float, default=2.0, help="wire height [m]")
    p.add_argument("--p", type=float, default=4.0, help="bellow pressure [bar]")
    p.add_argument("--parameters", help="parameter file (JSON)")
    p.add_argument("--json", help="also write the result as JSON")

    p = add("parameters", run_parameters, "write a model's default parameter file")
    p.add_argument("--model", default="Pantograph", choices=("Pantograph", "TwoMass", "ThreeMass"))
    p.add_argument("--out", required=True, help="JSON file to write")

    p = add("demo", run_demo, "the main job: FMUs, rig campaign, video, identification, "
            "diagnosis, next experiment, co-simulation; writes report.html and summary.json")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quick", action="store_true", help="reduced version (seconds)")

    for module in _COMMAND_MODULES:
        importlib.import_module(module).register(add)
    return parser, handlers


# Subcommands of the later packages live beside this file, one module per package; each module
# has ``register(add)`` where ``add(name, handler, help) -> ArgumentParser`` declares a subcommand.
_COMMAND_MODULES = ("panto.commands_cosim", "panto.commands_rig", "panto.commands_sync",
                    "panto.commands_video", "panto.commands_comparison",
                    "panto.commands_identification", "panto.commands_doe",
                    "panto.commands_diagnosis")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``panto`` console script."""
    parser, handlers = _parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return handlers[args.command](args)
    except (ValueError, OSError, RuntimeError) as error:
        print(f"panto {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
