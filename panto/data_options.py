"""The data options shared by ``panto identify``, ``panto compare`` and ``panto diagnose``.

:func:`add_data_options` declares them on a subcommand's parser; :func:`load_data` turns one file
and the parsed options into :class:`~panto.identification.estimation.base.IdentificationData`
through the library's :func:`panto.identification.data.loading.load_identification_data`:

- ``--inputs NAME=COLUMN ...``, ``--outputs NAME=COLUMN ...``: the columns of any table (CSV,
  Parquet, .mat, HDF5; suffixes in any case) or dataset; the physical and oscillator structures
  need inputs named ``eta`` and ``p`` (``--inputs eta=height p=pressure``);
- without them a recorded rig run uses the rig mapping (eta, p) -> (F_c, y_cb) when the command
  asks for it;
- ``--sample-rate HZ`` for a table without a ``time``/``t`` column, ``--rate HZ`` to decimate
  (rig runs: 50 Hz by default), ``--train-samples``/``--validate-samples START:STOP`` to select
  rows, ``--eta-offset`` for rig runs;
- ``--key NAME``: an HDF5 file's table when it holds several (``FILE.h5:NAME`` names one per
  file, e.g. two tables of one file to train and validate).

It also holds the checked option types every command uses (:func:`positive_float`,
:func:`positive_int`, :func:`non_negative_int`, :func:`non_negative_float`): a value out of range
is a usage error naming the option, the value and the allowed range, before any work.
"""
from __future__ import annotations

import argparse
import math
from typing import Any, Callable


class UsageError(ValueError):
    """A command line whose options do not go together: ``panto`` exits with code 2 (usage)."""


def parse_pairs(items: list[str] | None, flag: str) -> dict[str, str]:
    """``["a=x", "b=y,c=z"]`` -> ``{"a": "x", "b": "y", "c": "z"}``; a clear error names `flag`."""
    out = {}
    for item in items or []:
        for part in item.split(","):
            name, sep, value = part.partition("=")
            if not sep or not name.strip() or not value.strip():
                raise ValueError(f"{flag} {part!r}: expected NAME=VALUE")
            out[name.strip()] = value.strip()
    return out


def parse_rows(text: str | None, flag: str = "--train-samples") -> slice:
    """``"100:900"`` -> ``slice(100, 900)``; empty parts are open ends; None keeps every row."""
    if not text:
        return slice(None)
    start, _, stop = text.partition(":")
    try:
        rows = slice(int(start) if start else None, int(stop) if stop else None)
    except ValueError:
        raise ValueError(f"{flag} {text!r}: expected START:STOP (sample numbers)") from None
    if rows.start is not None and rows.stop is not None and (rows.start >= 0) == (rows.stop >= 0) \
            and rows.stop <= rows.start:
        raise ValueError(f"{flag} {text!r}: selects no rows; STOP must be greater than START")
    return rows


def _checked_number(kind: Callable[[str], Any], test: Callable[[Any], bool], allowed: str
                    ) -> Callable[[str], Any]:
    """An argparse ``type``: `kind` of the text, refused unless ``test(value)``."""

    def convert(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number ({allowed})") from None
        if isinstance(value, float) and not math.isfinite(value) or not test(value):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {allowed}")
        return value

    convert.__name__ = kind.__name__  # argparse names the type in its messages
    convert.__doc__ = (f"An argparse ``type``: the option's text as {kind.__name__}, refused "
                       f"unless it is {allowed}.")
    return convert


#: An argparse ``type``: a finite number > 0.
positive_float = _checked_number(float, lambda v: v > 0.0, "a number > 0")
#: An argparse ``type``: a finite number >= 0.
non_negative_float = _checked_number(float, lambda v: v >= 0.0, "a number >= 0")
#: An argparse ``type``: an integer >= 1.
positive_int = _checked_number(int, lambda v: v >= 1, "an integer >= 1")
#: An argparse ``type``: an integer >= 0.
non_negative_int = _checked_number(int, lambda v: v >= 0, "an integer >= 0")


def add_data_options(parser: argparse.ArgumentParser) -> None:
    """Declare the data options (module notes) on `parser`."""
    parser.add_argument("--inputs", nargs="*", metavar="NAME=COLUMN",
                        help="input signals from named columns (any table or dataset)")
    parser.add_argument("--outputs", nargs="*", metavar="NAME=COLUMN",
                        help="output signals from named columns (any table or dataset)")
    parser.add_argument("--rate", type=positive_float,
                        help="identification rate [Hz]: decimate to it (rig runs: 50)")
    parser.add_argument("--sample-rate", type=positive_float,
                        help="rate [Hz] of a table without a time column")
    parser.add_argument("--lowpass", type=positive_float, metavar="HZ",
                        help="tables: zero-phase low-pass [Hz] of every used column before the "
                             "rows are selected and the data decimated")
    parser.add_argument("--train-samples", metavar="START:STOP",
                        help="rows of the training file")
    parser.add_argument("--validate-samples", metavar="START:STOP",
                        help="rows of the validation file")
    parser.add_argument("--key", metavar="NAME",
                        help="HDF5 files: the table to read when a file holds several (or give "
                             "the file as FILE.h5:NAME)")
    parser.add_argument("--eta-offset", type=float,
                        help="rig runs: height of the motor's zero [m] (default from the run's "
                             "metadata)")


def load_data(path: str, args: argparse.Namespace, *, validation: bool = False,
              rig_mapping: bool, **rig: Any) -> Any:
    """One file's identification data from the parsed data options.

    Parameters
    ----------
    path : str
        Run folder or file.
    args : argparse.Namespace
        Parsed options of :func:`add_data_options`.
    validation : bool
        The file is the validation run (``--validate-samples`` select its rows), not the
        training run (``--train-samples``).
    rig_mapping : bool
        Whether a recorded run without named columns uses the rig mapping.
    **rig
        Further :class:`~panto.identification.data.loading.LoadOptions` fields (``start``,
        ``stop``, ``rig_outputs``, ``cross_bar``, ``position_latency``).
    """
    from panto.identification.data.loading import LoadOptions, load_identification_data

    options = LoadOptions(inputs=parse_pairs(args.inputs, "--inputs"),
                          outputs=parse_pairs(args.outputs, "--outputs"), rate=args.rate,
                          sample_rate=args.sample_rate, rows=_rows(args, validation),
                          eta_offset=args.eta_offset, rig_mapping=rig_mapping,
                          lowpass=getattr(args, "lowpass", None),
                          key=getattr(args, "key", None), **rig)
    return load_identification_data(path, options)


def _rows(args: argparse.Namespace, validation: bool) -> slice:
    if validation:
        return parse_rows(args.validate_samples, "--validate-samples")
    return parse_rows(args.train_samples, "--train-samples")
