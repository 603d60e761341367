"""Build and validate all of the project's FMUs (what ``panto build-fmu`` does)."""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from fmu_src.models import FMU_NAMES, model_spec

from .build import build_fmu
from .validate import validate_fmu

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BuiltFmu:
    """One built FMU and what fmpy's validator said about it."""

    name: str
    fmi_version: int
    path: Path
    problems: tuple[str, ...]
    seconds: float


def build_project_fmus(
    out_dir: str | Path,
    *,
    names: Sequence[str] = FMU_NAMES,
    fmi_versions: Sequence[int] = (2, 3),
    validate: bool = True,
    progress: Callable[[str], None] | None = None,
) -> list[BuiltFmu]:
    """Generate, compile, package and validate the FMUs.

    Parameters
    ----------
    out_dir : path
        Folder for the ``.fmu`` files (created).
    names : sequence of str
        Models to build (default: Pantograph, PantographLinear, TwoMass, ThreeMass).
    fmi_versions : sequence of int
        2 and/or 3.
    validate : bool
        Run fmpy's validator on every FMU.
    progress : callable, optional
        Called with one line of text per step.

    Returns
    -------
    list of BuiltFmu
    """
    unknown = sorted(set(names) - set(FMU_NAMES))
    if unknown:
        raise ValueError(f"unknown FMU(s) {unknown}; choose from {list(FMU_NAMES)}")
    say = progress or log.info
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    built = []
    for name in names:
        start = time.perf_counter()
        say(f"{name}: generating C code from the symbolic model")
        spec = model_spec(name)
        for version in fmi_versions:
            path = build_fmu(spec, out, fmi_version=version)
            problems = tuple(validate_fmu(path)) if validate else ()
            verdict = "valid" if not problems else f"{len(problems)} problem(s): {problems[0]}"
            say(f"{name}: FMI {version}.0 -> {path.name} ({verdict})")
            built.append(BuiltFmu(name, version, path, problems, time.perf_counter() - start))
            start = time.perf_counter()
    return built
