"""Write an FMU's C sources and compile them into a shared library with the machine's compiler.

``sources/`` holds everything needed to rebuild the binary anywhere: the generated model
(``model.c``), the generated ``model_config.h``, the hand-written runtime of
``fmu_src/runtime`` (the FMI front end of the requested version only) and the FMI headers.
"""
from __future__ import annotations

import logging
import os
import shutil
import subprocess
from pathlib import Path

from panto.fmu_src.spec import RUNTIME_DIR

LOGGER = logging.getLogger(__name__)

#: Runtime files shared by both FMI versions.
CORE_FILES = ("fmu_core.h", "fmu_core.c", "fmu_state.c", "fmu_numerics.c", "fmu_solver.c",
              "model_interface.h")
#: The FMI front end and standard headers of each version.
VERSION_FILES = {
    2: ("fmi2_functions.c", "include/fmi2Functions.h", "include/fmi2FunctionTypes.h",
        "include/fmi2TypesPlatform.h"),
    3: ("fmi3_functions.c", "fmi3_model_structure.c", "fmi3_unsupported.c", "fmi3_front_end.h",
        "include/fmi3Functions.h", "include/fmi3FunctionTypes.h", "include/fmi3PlatformTypes.h"),
}
MODEL_SOURCE_NAME = "model.c"
CONFIGURATION_NAME = "model_config.h"
COMPILER_FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall",
                  "-Wextra")


class CompilationError(RuntimeError):
    """The C compiler failed; the message carries the command and the compiler's output."""


def read_runtime_sources(fmi_version: int) -> dict[str, str]:
    """The runtime files of one FMI version, by file name (without directories).

    Parameters
    ----------
    fmi_version : int
        2 or 3.

    Returns
    -------
    dict of str to str
        File name → text.
    """
    if fmi_version not in VERSION_FILES:
        raise ValueError(f"fmi_version must be 2 or 3, got {fmi_version!r}")
    files = {}
    for relative in CORE_FILES + VERSION_FILES[fmi_version]:
        path = RUNTIME_DIR / relative
        if not path.is_file():
            raise FileNotFoundError(f"runtime file missing: {path}")
        files[Path(relative).name] = path.read_text(encoding="utf-8")
    return files


def write_sources(directory: Path, fmi_version: int, model_code: str,
                  configuration: str) -> tuple[str, ...]:
    """Write all C sources and headers of one FMU into ``directory``.

    Parameters
    ----------
    directory : Path
        The ``sources/`` folder (created if missing).
    fmi_version : int
        2 or 3.
    model_code : str
        The generated model (implements ``model_interface.h``).
    configuration : str
        The generated ``model_config.h``.

    Returns
    -------
    tuple of str
        The names of the files written, sorted.
    """
    directory.mkdir(parents=True, exist_ok=True)
    files = read_runtime_sources(fmi_version)
    files[MODEL_SOURCE_NAME] = model_code
    files[CONFIGURATION_NAME] = configuration
    for name, text in files.items():
        (directory / name).write_text(text, encoding="utf-8")
    return tuple(sorted(files))


def find_compiler() -> str:
    """The C compiler: ``$CC``, else ``cc``, else ``gcc``.

    Raises
    ------
    CompilationError
        If none is found.
    """
    candidates = [os.environ.get("CC"), "cc", "gcc"]
    for candidate in candidates:
        if candidate and shutil.which(candidate):
            return candidate
    raise CompilationError("no C compiler found (tried $CC, cc, gcc); install gcc or set CC")


def compile_library(sources: Path, output: Path) -> Path:
    """Compile every ``.c`` file in ``sources`` into the shared library ``output``.

    Only the ``fmi2*``/``fmi3*`` functions are exported (``-fvisibility=hidden``).

    Parameters
    ----------
    sources : Path
        Folder written by :func:`write_sources`.
    output : Path
        Path of the library to create (its folder is created).

    Returns
    -------
    Path
        ``output``.

    Raises
    ------
    CompilationError
        With the command and the compiler's messages, if compilation fails.
    """
    output.parent.mkdir(parents=True, exist_ok=True)
    c_files = sorted(str(path) for path in sources.glob("*.c"))
    command = [find_compiler(), *COMPILER_FLAGS, "-I", str(sources), "-o", str(output),
               *c_files, "-lm"]
    LOGGER.info("compiling %s", output.name)
    LOGGER.debug("%s", " ".join(command))
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise CompilationError(f"compiling {output.name} failed (exit code {result.returncode})"
                               f"\ncommand: {' '.join(command)}\n{result.stderr}{result.stdout}")
    if result.stderr.strip():
        LOGGER.warning("compiler warnings for %s:\n%s", output.name, result.stderr)
    return output
