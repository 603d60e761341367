"""Build and validate all of the project's FMUs (what ``panto build-fmu`` does)."""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from panto.fmu_src.models import FMU_NAMES, model_spec

from .build import build_fmu
from .compile import find_zig
from .package import fmu_platforms
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
    cross: bool = False,
) -> list[BuiltFmu]:
    """Generate, compile, package and validate the FMUs.

    Parameters
    ----------
    out_dir : path
        Folder for the ``.fmu`` files (created).
    names : sequence of str
        Models to build (default: all of ``FMU_NAMES``: Pantograph, PantographLinear, TwoMass,
        ThreeMass and their force-excited forms PantographForce, PantographForceLinear,
        TwoMassForce, ThreeMassForce).
    fmi_versions : sequence of int
        2 and/or 3.
    validate : bool
        Run fmpy's validator on every FMU.
    progress : callable, optional
        Called with one line of text per step.
    cross : bool
        Cross-compile every FMU for Windows, macOS and aarch64 Linux too (needs ``ziglang``;
        without it the FMUs carry this machine's binary only, said in one line). Default off
        (about 4 s of CPU per FMU here); ``panto build-fmu`` turns it on.

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
    if cross and find_zig() is None:
        say("ziglang is not installed: the FMUs carry only this machine's binary "
            "(pip install ziglang for Windows, macOS and aarch64 Linux)")
    for name in names:
        start = time.perf_counter()
        say(f"{name}: generating C code from the symbolic model")
        spec = model_spec(name)
        for version in fmi_versions:
            path = build_fmu(spec, out, fmi_version=version, cross=cross)
            problems = tuple(validate_fmu(path)) if validate else ()
            verdict = "valid" if not problems else f"{len(problems)} problem(s): {problems[0]}"
            say(f"{name}: FMI {version}.0 -> {path.name} ({verdict}; "
                f"{', '.join(fmu_platforms(path))})")
            built.append(BuiltFmu(name, version, path, problems, time.perf_counter() - start))
            start = time.perf_counter()
    return built


# --- project FMUs built on demand into a cache ---------------------------------------------------

#: Environment variable naming the FMU cache folder (default ``~/.cache/panto/fmus``).
CACHE_VARIABLE = "PANTO_FMU_CACHE"


def _source_digest() -> str:
    """Hash of the model and FMU-builder sources: a new cache folder when they change."""
    root = Path(__file__).resolve().parent.parent  # the source tree (editable install)
    digest = hashlib.sha256()
    for folder in ("fmu_src", "build_fmu"):
        for path in sorted((root / folder).rglob("*")):
            if path.is_file() and path.suffix in (".py", ".c", ".h"):
                digest.update(path.relative_to(root).as_posix().encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:12]


def default_cache_dir() -> Path:
    """``$PANTO_FMU_CACHE`` or ``~/.cache/panto/fmus``, in a sub-folder per source version."""
    base = os.environ.get(CACHE_VARIABLE) or Path.home() / ".cache" / "panto" / "fmus"
    return Path(base) / _source_digest()


def project_fmu(name: str, *, cache_dir: str | Path | None = None,
                progress: Callable[[str], None] | None = None) -> Path:
    """The FMI 2.0 FMU of a project model, built into the cache folder if not there yet.

    It carries this machine's binary only (it runs here; ``panto build-fmu`` cross-compiles).

    Built in a temporary folder and moved into place, so parallel workers never see half a
    file.
    """
    if name not in FMU_NAMES:
        raise ValueError(f"unknown project FMU {name!r}; choose one of {list(FMU_NAMES)}")
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    target = folder / f"{name}.fmu"
    if target.exists():
        return target
    folder.mkdir(parents=True, exist_ok=True)
    if progress:
        progress(f"building the {name} FMU into {folder}")
    with tempfile.TemporaryDirectory(dir=folder) as scratch:
        built = build_project_fmus(scratch, names=[name], fmi_versions=(2,), cross=False)
        problems = [p for b in built for p in b.problems]
        if problems:
            raise RuntimeError(f"the {name} FMU did not validate: {problems}")
        os.replace(built[0].path, target)
    return target
