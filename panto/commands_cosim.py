"""``panto cosim``: pantograph FMU against a finite-difference catenary (issue 3)."""
from __future__ import annotations

from typing import Callable


def register(add: Callable) -> None:
    """Declare this package's subcommands with ``add(name, handler, help)``."""
