"""What the command line prints: one line at a time on standard output, flushed at once."""
from __future__ import annotations


def say(line: str) -> None:
    """Print `line` to standard output and flush (progress shows while a command runs)."""
    print(line, flush=True)
