"""``panto``: the command-line interface. Each subcommand is one small function in a table.

:func:`main` parses, checks the paths it is given (an FMU that is no FMU, an output that cannot
be written) before any work, runs the subcommand and turns its end into an exit code
(:data:`EXIT_CODES`): bad input is one line on standard error naming the culprit, never a
traceback; Ctrl-C keeps what was recorded and says so in one line; a closed pipe ends quietly.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback
from pathlib import Path
from typing import Callable, Iterator

from panto import console
from panto.fmu_src.frame_stack import keep_stack_chunks
from panto.console import progress, say
from panto.data_options import UsageError, non_negative_float

#: Exit codes of every ``panto`` command (shown by ``panto --help``).
EXIT_CODES = {0: "success",
              1: "the command ran, and its result is negative (a fit that failed, a check "
                 "outside its limits, aliasing suspected)",
              2: "usage error: an unknown option, a missing argument, an option value out "
                 "of its range (found before any work); one line names it",
              3: "internal error (a bug: run with -v for the traceback and report it)",
              4: "aborted (Ctrl-C); what was recorded so far is kept",
              65: "bad input data (as sysexits' EX_DATAERR): a file missing, malformed or "
                  "implausible, a column, a value, an output that cannot be written, an option "
                  "that does not fit the data; one line names it",
              141: "standard output closed early (e.g. piped into head): ends quietly"}


def run_build_fmu(args: argparse.Namespace) -> int:
    """Build, validate and list the FMUs."""
    from panto.build_fmu.project import build_project_fmus

    built = build_project_fmus(args.out, names=args.models or _all_fmus(),
                               fmi_versions=args.fmi_version, progress=progress,
                               cross=not args.host_only)
    failed = [b for b in built if b.problems]
    for b in failed:
        say(f"INVALID {b.path}: " + "; ".join(b.problems))
    return 1 if failed else 0


def _all_fmus():
    from panto.fmu_src.models import FMU_NAMES

    return FMU_NAMES


def run_linearise(args: argparse.Namespace) -> int:
    """Static equilibrium and linearisation about an operating point."""
    from panto.fmu_src.models import FORCE_FMU_NAMES, Model, load_parameters
    from panto.fmu_src.operating_point import force_model_inputs

    params = load_parameters(args.parameters, args.model) if args.parameters else None
    model = Model(args.model, params)
    inputs = {"eta": args.eta, "p": args.p}
    if args.model in FORCE_FMU_NAMES:  # held where the displacement twin rests at (eta, p)
        inputs = force_model_inputs(args.model, args.eta, args.p, model.parameters)
        say("inputs: " + ", ".join(f"{name} = {value:.6g}" for name, value in inputs.items()))
    lin = model.linearise(*inputs.values())
    result = {
        "model": args.model, "eta": args.eta, "p": args.p, "inputs": inputs,
        "equilibrium": dict(zip(lin.state_names, lin.x0.tolist())),
        "outputs": dict(zip(lin.output_names, lin.y0.tolist())),
        "eigenvalues": [[ev.real, ev.imag] for ev in lin.eigenvalues],
        "natural_frequencies_hz": lin.natural_frequencies_hz.tolist(),
        "A": lin.A.tolist(), "B": lin.B.tolist(), "C": lin.C.tolist(), "D": lin.D.tolist(),
    }
    for name, value in result["outputs"].items():
        say(f"{name:>6} = {value:.6g}")
    say("modes [Hz]: " + ", ".join(f"{f:.3f}" for f in lin.natural_frequencies_hz))
    unstable = lin.eigenvalues[lin.eigenvalues.real > 0]
    if unstable.size:
        say("unstable eigenvalues [1/s]: " + ", ".join(
            f"{ev.real:+.4g}" + (f" {ev.imag:+.4g}j" if ev.imag else "") for ev in unstable))
    if args.json:
        console.write_json(args.json, result)
    return 0


#: The models ``panto linearise`` and ``panto parameters`` offer: displacement- and force-excited.
_MODELS = ("Pantograph", "TwoMass", "ThreeMass", "PantographForce", "TwoMassForce",
           "ThreeMassForce")


def run_parameters(args: argparse.Namespace) -> int:
    """Write a model's default parameter file (values, units, bounds, provenance)."""
    from panto.fmu_src.models import default_parameters

    path = default_parameters(args.model).save(args.out)
    say(f"wrote {path}")
    return 0


def run_demo(args: argparse.Namespace) -> int:
    """The main job on the embedded defaults."""
    from panto.demo import DemoError, run_demo as demo

    try:
        demo(Path(args.out), quick=args.quick, progress=progress)
    except DemoError as failed:  # the run ended; its result is negative (code 1)
        return _fail("demo", str(failed), 1)
    return 0


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line on standard error (exit code 2)."""

    def error(self, message: str):
        """Print ``<prog>: error: <message> (see <prog> --help)`` and exit with code 2."""
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _version() -> str:
    from panto import __version__

    return __version__


def _epilog() -> str:
    return "exit codes:\n" + "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())


def _add_verbosity(parser: argparse.ArgumentParser, *, top: bool) -> None:
    """``-v``/``-q`` on `parser`; a subcommand's count apart from the top's (they add up)."""
    after = "" if top else "_after"
    parser.add_argument("-v", "--verbose", action="count", default=0, dest="verbose" + after,
                        help="more on standard error: -v every progress line with its time, "
                             "debug records and an internal error's traceback; -vv also "
                             "third-party libraries' records")
    parser.add_argument("-q", "--quiet", action="store_true", dest="quiet" + after,
                        help="no progress on standard error, only warnings and errors; results "
                             "still on standard output")


def verbosity(args: argparse.Namespace) -> int:
    """The :mod:`panto.console` level of the parsed `args` (``-q``: -1, none: 0, ``-vv``: 2).

    ``-v`` and ``-q`` count before and after the subcommand alike; ``-q`` wins.
    """
    if args.quiet or getattr(args, "quiet_after", False):
        return console.QUIET
    return min(console.DEBUG, args.verbose + getattr(args, "verbose_after", 0))


def walk_parsers(parser: argparse.ArgumentParser) -> Iterator[argparse.ArgumentParser]:
    """`parser` and every subcommand parser below it, depth first."""
    yield parser
    for action in parser._actions:  # argparse keeps its subparsers there (no public accessor)
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                yield from walk_parsers(child)


def _parser() -> tuple[argparse.ArgumentParser, dict[str, Callable]]:
    parser = _Parser(prog="panto", description=__doc__.split("\n")[0], epilog=_epilog(),
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"panto {_version()}",
                        help="print the version and exit")
    _add_verbosity(parser, top=True)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser,
                                help="the subcommand; 'panto COMMAND --help' for its options")
    handlers: dict[str, Callable] = {}

    def add(name: str, handler: Callable, help_text: str) -> argparse.ArgumentParser:
        handlers[name] = handler
        return sub.add_parser(name, help=help_text, description=help_text,
                              epilog="exit codes: see panto --help")

    p = add("build-fmu", run_build_fmu, "generate, compile, package and validate the FMUs")
    p.add_argument("--out", default="fmus", help="output folder (default: fmus)")
    p.add_argument("--models", nargs="*", help="subset, e.g. Pantograph TwoMass")
    p.add_argument("--fmi-version", type=int, nargs="+", choices=(2, 3), default=[2, 3],
                   help="FMI versions to build (default: 2 3)")
    p.add_argument("--host-only", action="store_true",
                   help="only this machine's binary (default: also Windows, macOS and aarch64 "
                        "Linux, cross-compiled with ziglang)")

    p = add("linearise", run_linearise, "equilibrium, eigenvalues and A, B, C, D at (eta, p)")
    p.add_argument("--model", default="Pantograph", choices=_MODELS,
                   help="model (default Pantograph)")
    p.add_argument("--eta", type=float, default=2.0,
                   help="wire height [m]; a force-excited model is held where its displacement "
                        "twin rests at (eta, p): its contact force and bellow torque k_p p")
    p.add_argument("--p", type=non_negative_float, default=4.0,
                   help="bellow pressure [bar] (>= 0)")
    p.add_argument("--parameters", help="parameter file (JSON)")
    p.add_argument("--json", help="also write the result as JSON")

    p = add("parameters", run_parameters, "write a model's default parameter file")
    p.add_argument("--model", default="Pantograph", choices=_MODELS,
                   help="model (default Pantograph)")
    p.add_argument("--out", required=True, help="JSON file to write")

    p = add("demo", run_demo, "the main job: FMUs, rig campaign, video, identification, "
            "diagnosis, next experiment, co-simulation; writes report.html and summary.json")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quick", action="store_true", help="reduced version (seconds)")

    for module in _COMMAND_MODULES:
        importlib.import_module(module).register(add)
    for child in list(walk_parsers(parser))[1:]:
        _add_verbosity(child, top=False)
    return parser, handlers


# Subcommands of the later packages live beside this file, one module per package; each module
# has ``register(add)`` where ``add(name, handler, help) -> ArgumentParser`` declares a subcommand.
_COMMAND_MODULES = ("panto.commands_cosim", "panto.commands_rig", "panto.commands_sync",
                    "panto.commands_video", "panto.commands_comparison",
                    "panto.commands_identification", "panto.commands_doe",
                    "panto.commands_diagnosis")


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``panto`` console script: the exit code (:data:`EXIT_CODES`)."""
    parser, handlers = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help, --version, a usage error
        return done.code if isinstance(done.code, int) else 2
    keep_stack_chunks()  # every command's loops without CPython 3.11's chunk thrashing
    level = verbosity(args)
    console.set_verbosity(level, json_to_stdout=getattr(args, "json", None) == "-")
    try:
        return _run(args, handlers[args.command], traceback_wanted=level >= console.VERBOSE)
    finally:
        console.reset()


def _run(args: argparse.Namespace, handler: Callable[[argparse.Namespace], int], *,
         traceback_wanted: bool) -> int:
    """Check the paths, run `handler`, and map how it ended to an exit code.

    A :class:`~panto.data_options.UsageError` is a usage error (2); a ``ValueError``,
    ``OSError`` or ``RuntimeError`` (bad input refused in words by the library) is bad input
    (65); any other exception, a ``KeyError`` or ``IndexError`` among them, is a bug (3).
    """
    name = " ".join(filter(None, (args.command, getattr(args, "rig_command", None),
                                  getattr(args, "video_command", None))))
    try:
        _check_paths(args)
        code = handler(args)
        sys.stdout.flush()
        return code
    except BrokenPipeError:  # the reader of standard output went away (| head): end quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except UsageError as error:
        return _fail(name, f"{error} (see panto {name} --help)", 2)
    except _BUG_CLASSES as error:
        return _internal(name, error, traceback_wanted)
    except (ValueError, OSError, RuntimeError) as error:
        return _fail(name, str(error), 65)
    except KeyboardInterrupt:
        return _fail(name, "aborted (Ctrl-C); what was written so far is kept", 4, "")
    except SystemExit as done:
        if isinstance(done.code, str):  # a command refusing its input in words
            _fail(name, done.code, 65)
            raise _Refused(done.code) from None
        raise
    except Exception as error:  # a bug: one line; the traceback with -v
        return _internal(name, error, traceback_wanted)


#: Subclasses of the bad-input classes that are bugs, not refusals.
_BUG_CLASSES = (NotImplementedError, RecursionError, UnicodeEncodeError)


def _internal(name: str, error: BaseException, traceback_wanted: bool) -> int:
    """Report a bug in one line (its traceback first under ``-v``): exit code 3."""
    if traceback_wanted:
        traceback.print_exception(error, file=sys.stderr)
    return _fail(name, f"internal error: {type(error).__name__}: {error} (run with -v for "
                       "the traceback)", 3)


class _Refused(SystemExit):
    """A command's refusal (:class:`SystemExit` with a message) once reported: exit code 65."""

    @property
    def code(self) -> int:
        """Exit code 65 (bad input); the message is in ``args``."""
        return 65


def _fail(name: str, message: str, code: int, label: str = "error: ") -> int:
    """Report `message` in one line on standard error; return `code`."""
    print(f"panto {name}: {label}{' '.join(message.split())}", file=sys.stderr, flush=True)
    return code


def _check_paths(args: argparse.Namespace) -> None:
    """Before any work: an ``--fmu`` must be an FMU, outputs must be writable."""
    fmu = getattr(args, "fmu", None)
    if fmu:
        _check_fmu(Path(fmu))
    for flag in ("out", "json", "plot", "picture"):
        value = getattr(args, flag, None)
        if isinstance(value, str) and value != "-":
            _check_writable(Path(value), f"--{flag}")


def _check_fmu(path: Path) -> None:
    import zipfile

    if not path.is_file():
        raise ValueError(f"--fmu {path}: no such file")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"--fmu {path}: not an FMU (an FMU is a zip archive with "
                         "modelDescription.xml)")
    with zipfile.ZipFile(path) as archive:
        if "modelDescription.xml" not in archive.namelist():
            raise ValueError(f"--fmu {path}: not an FMU (no modelDescription.xml in the archive)")


def _check_writable(path: Path, flag: str) -> None:
    """`path` can be created or written: its nearest existing ancestor is a writable folder."""
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if existing != path and not existing.is_dir():
        raise ValueError(f"{flag} {path}: cannot be created, {existing} is a file, not a folder")
    folder = existing if existing.is_dir() else existing.parent
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path}: cannot be written, no permission in {folder}")


if __name__ == "__main__":
    sys.exit(main())
