"""``panto rig``: the rig sidecar and the virtual test bed (issue 4)."""
from __future__ import annotations

from typing import Callable


def register(add: Callable) -> None:
    """Declare this package's subcommands with ``add(name, handler, help)``."""
