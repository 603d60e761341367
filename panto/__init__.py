"""``panto``: a physically based high-speed pantograph as FMUs, with catenary co-simulation,
identification, design of experiments, the rig's sidecars and the sim-to-real gap diagnosis.

Everything installs under this one name (``docs/architecture.md``): ``panto.fmu_src`` (models),
``panto.build_fmu`` (FMUs), ``panto.catenary_cosim``, ``panto.rig``, ``panto.video_sync``,
``panto.identification``; the modules of this folder are the ``panto`` command line and the demo.

:func:`lazy_exports` gives each package its public names, imported on first use, so that
``from panto.rig import read_dataset`` works and ``import panto.rig`` stays cheap.
"""
from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from typing import Any, Callable, Mapping

try:
    #: The installed distribution's version (package metadata, from ``pyproject.toml``).
    __version__ = version("panto")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"


def lazy_exports(package: str, table: Mapping[str, str]
                 ) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``__all__``, ``__getattr__`` and ``__dir__`` for `package`, re-exporting ``name`` from its
    submodule ``table[name]`` (relative to the package) when first asked for (PEP 562)."""

    def attribute(name: str) -> Any:
        if name not in table:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(import_module(f"{package}.{table[name]}"), name)

    names = sorted(table)
    return names, attribute, lambda: names
