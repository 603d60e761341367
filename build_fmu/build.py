"""Build an FMU from a :class:`~panto.fmu_src.spec.ModelSpec`: the one entry point of the package.

Phases: lay out the variables → derive the instantiation token → write the model description
(and, for FMI 3.0, the build description) → write the C sources → compile (for every
platform with ziglang) → zip.
"""
from __future__ import annotations

import hashlib
import logging
import tempfile
from pathlib import Path

from panto.fmu_src.spec import ModelSpec

from .compile import compile_binaries, read_runtime_sources, write_sources
from .configuration import write_model_config
from .description_fmi2 import write_model_description_fmi2
from .description_fmi3 import write_build_description, write_model_description_fmi3
from .package import package_fmu
from .variables import FmuVariable, layout_variables

LOGGER = logging.getLogger(__name__)


def make_fmu_file_name(identifier: str, fmi_version: int) -> str:
    """``<identifier>.fmu`` for FMI 2.0, ``<identifier>_fmi3.fmu`` for FMI 3.0."""
    return f"{identifier}.fmu" if fmi_version == 2 else f"{identifier}_fmi3.fmu"


def derive_instantiation_token(spec: ModelSpec, variables: tuple[FmuVariable, ...],
                               fmi_version: int) -> str:
    """A GUID-formatted token that changes whenever anything inside the FMU changes.

    It is the SHA-256 of the FMI version, the model's identity and description, its variable
    table, its C code and the runtime sources, formatted as ``{8-4-4-4-12}``.

    Parameters
    ----------
    spec : ModelSpec
    variables : tuple of FmuVariable
    fmi_version : int

    Returns
    -------
    str
    """
    digest = hashlib.sha256()
    for part in (f"FMI {fmi_version}", spec.identifier, spec.description,
                 repr(spec.linearised), repr(variables), repr(spec.dependencies), spec.c_code,
                 *(f"{name}\n{text}" for name, text in
                   sorted(read_runtime_sources(fmi_version).items()))):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    h = digest.hexdigest()
    return f"{{{h[0:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}}}"


def _write_descriptions(staging: Path, spec: ModelSpec, variables: tuple[FmuVariable, ...],
                        token: str, fmi_version: int, source_files: tuple[str, ...]) -> None:
    if fmi_version == 2:
        text = write_model_description_fmi2(spec, variables, token, source_files)
    else:
        text = write_model_description_fmi3(spec, variables, token)
        (staging / "sources" / "buildDescription.xml").write_text(
            write_build_description(spec, source_files), encoding="utf-8")
    (staging / "modelDescription.xml").write_text(text, encoding="utf-8")


def build_fmu(spec: ModelSpec, out_dir: str | Path, *, fmi_version: int,
              cross: bool = False) -> Path:
    """Build, compile and package one FMU (Model Exchange and Co-Simulation).

    Parameters
    ----------
    spec : ModelSpec
        The model; ``spec.c_code`` implements ``fmu_src/runtime/model_interface.h`` and is used
        as it is. A linearised spec (``spec.linearised``) gets deviation states
        ``delta_<state>`` and operating-point parameters ``<input>0``.
    out_dir : str or Path
        Folder for the ``.fmu`` (created if missing).
    fmi_version : int
        2 or 3 (keyword only).
    cross : bool
        Also cross-compile for Windows, macOS and aarch64 Linux when ``ziglang`` is installed
        (a failing target is left out with a warning); default: the host's library only.

    Returns
    -------
    Path
        ``out_dir/<identifier>.fmu`` (FMI 2.0) or ``out_dir/<identifier>_fmi3.fmu`` (FMI 3.0).

    Raises
    ------
    ValueError
        For an unknown FMI version or an inconsistent spec (names, units, ranges).
    panto.build_fmu.compile.CompilationError
        If the C code does not compile; the message holds the compiler output.
    """
    if fmi_version not in (2, 3):
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    variables = layout_variables(spec)
    token = derive_instantiation_token(spec, variables, fmi_version)
    destination = Path(out_dir) / make_fmu_file_name(spec.identifier, fmi_version)
    LOGGER.info("building %s (FMI %d.0, %d variables)", destination.name, fmi_version,
                len(variables))
    with tempfile.TemporaryDirectory(prefix=f"build_{spec.identifier}_") as temporary:
        staging = Path(temporary)
        source_files = write_sources(staging / "sources", fmi_version, spec.c_code,
                                     write_model_config(spec, variables, token))
        _write_descriptions(staging, spec, variables, token, fmi_version, source_files)
        compile_binaries(staging / "sources", staging, spec.identifier, fmi_version,
                         cross=cross)
        return package_fmu(staging, destination)
