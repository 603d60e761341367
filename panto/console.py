"""What the command line prints: one line at a time on standard output, flushed at once.

:func:`say` prints results; :func:`progress` prints the lines that say how a run goes, which
``panto --quiet`` (:func:`set_verbosity`) silences. Errors go to standard error (``panto.cli``).
"""
from __future__ import annotations

_QUIET = False


def say(line: str) -> None:
    """Print `line` to standard output and flush (progress shows while a command runs)."""
    print(line, flush=True)


def progress(line: str) -> None:
    """Print a progress line to standard output (flushed), unless ``--quiet`` was given."""
    if not _QUIET:
        print(line, flush=True)


def set_verbosity(*, quiet: bool) -> None:
    """Silence (`quiet`) or restore :func:`progress` for the rest of the command."""
    global _QUIET
    _QUIET = quiet
