"""Write an FMU's C sources and compile them into shared libraries for every platform.

With ``ziglang`` installed, ``zig cc`` builds the host's library (Linux against a glibc 2.17
baseline) and, on request, cross-compiles it for every platform of
:data:`~panto.build_fmu.package.PLATFORMS` (Windows, macOS, aarch64 Linux; FMI 2.0's
``darwin64`` is a universal x86_64 + arm64 library); without it the machine's own C compiler
builds the host's library only.

``sources/`` holds everything needed to rebuild the binary anywhere: the generated model
(``model.c``), the generated ``model_config.h``, the hand-written runtime of
``fmu_src/runtime`` (the FMI front end of the requested version only) and the FMI headers.
"""
from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import shutil
import struct
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from panto.fmu_src.spec import RUNTIME_DIR

from .package import PLATFORMS, host_platform, make_binary_path, platform_binary_path

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
#: Extra flags of ``zig cc`` builds: no debug information, stripped (exports stay).
ZIG_FLAGS = ("-g0", "-s")


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


def find_zig() -> list[str] | None:
    """The command that runs ziglang's ``zig``, or None if ``ziglang`` is not installed."""
    spec = importlib.util.find_spec("ziglang")
    if spec is None or spec.origin is None:
        return None
    executable = Path(spec.origin).parent / ("zig.exe" if os.name == "nt" else "zig")
    return [str(executable)] if executable.is_file() else [sys.executable, "-m", "ziglang"]


def compile_library(sources: Path, output: Path, *, zig_target: str | None = None) -> Path:
    """Compile every ``.c`` file in ``sources`` into the shared library ``output``.

    Only the ``fmi2*``/``fmi3*`` functions are exported (``-fvisibility=hidden``; on Windows
    ``__declspec(dllexport)`` of the FMI headers).

    Parameters
    ----------
    sources : Path
        Folder written by :func:`write_sources`.
    output : Path
        Path of the library to create (its folder is created).
    zig_target : str, optional
        Cross-compile with ``zig cc -target zig_target``; default: the machine's compiler.

    Returns
    -------
    Path
        ``output``.

    Raises
    ------
    CompilationError
        With the command and the compiler's messages, if compilation fails (or ``zig_target``
        is given and ziglang is not installed).
    """
    output.parent.mkdir(parents=True, exist_ok=True)
    if zig_target is None:
        compiler = [find_compiler(), *COMPILER_FLAGS]
    else:
        zig = find_zig()
        if zig is None:
            raise CompilationError("ziglang is not installed (pip install ziglang)")
        compiler = [*zig, "cc", "-target", zig_target, *COMPILER_FLAGS, *ZIG_FLAGS]
        sources = content_addressed(sources)
    c_files = sorted(str(path.resolve()) for path in sources.glob("*.c"))
    with tempfile.TemporaryDirectory(prefix="cc_") as scratch:  # side files (.pdb, .lib) stay
        built = Path(scratch) / output.name
        command = [*compiler, "-I", str(sources.resolve()), "-o", str(built), *c_files, "-lm"]
        LOGGER.info("compiling %s%s", output.name, f" for {zig_target}" if zig_target else "")
        LOGGER.debug("%s", " ".join(command))
        result = subprocess.run(command, capture_output=True, text=True, check=False,
                                cwd=scratch)
        if result.returncode != 0:
            raise CompilationError(f"compiling {output.name} failed (exit code "
                                   f"{result.returncode})\ncommand: {' '.join(command)}\n"
                                   f"{result.stderr}{result.stdout}")
        shutil.move(str(built), output)
    if result.stderr.strip():
        LOGGER.warning("compiler warnings for %s:\n%s", output.name, result.stderr)
    return output


#: Folder (under the system's temporary folder) of the sources' content-addressed copies.
SOURCE_COPIES = "panto-fmu-sources"


def content_addressed(sources: Path) -> Path:
    """The files of `sources` in a folder named by their names and bytes, written once and
    never touched again: ``zig cc`` keys its cache on the input files' paths and reuses a
    build only for files it has seen unchanged there, so the same FMU sources compiled again
    (from another FMU's fresh ``sources/`` folder) take its cached library, the same bytes,
    instead of a new compilation (about 0.6 s of CPU for a small model). `sources` itself where
    the copy cannot be written (a read-only temporary folder, another user's folder)."""
    files = sorted(path for path in sources.iterdir() if path.is_file())
    digest = hashlib.sha256()
    for path in files:
        data = path.read_bytes()
        digest.update(f"{path.name}\0{len(data)}\0".encode())
        digest.update(data)
    root = Path(tempfile.gettempdir()) / SOURCE_COPIES
    target = root / digest.hexdigest()[:32]
    if target.is_dir():
        return target
    try:
        root.mkdir(exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=".part_", dir=root))
        for path in files:
            shutil.copyfile(path, scratch / path.name)
        try:
            scratch.rename(target)  # whole or not at all; another process may have won
        except OSError:
            shutil.rmtree(scratch, ignore_errors=True)
    except OSError as error:
        LOGGER.debug("no content-addressed copy of %s (%s): compiling in place", sources, error)
        return sources
    return target if target.is_dir() else sources


@dataclass(frozen=True)
class CompiledBinaries:
    """What :func:`compile_binaries` put into an FMU.

    Attributes
    ----------
    platforms : tuple of str
        The FMI 3.0 platform tuples a library was built for.
    failed : tuple of str
        The platforms whose cross-compilation failed (the FMU carries the others).
    """

    platforms: tuple[str, ...]
    failed: tuple[str, ...]


def compile_binaries(sources: Path, staging: Path, identifier: str, fmi_version: int, *,
                     cross: bool = False) -> CompiledBinaries:
    """Compile the FMU's library for the host and, if asked, for every other platform.

    With ziglang the host's library is built by ``zig cc`` too (Linux: against glibc 2.17, so
    it loads on older distributions), falling back to the machine's compiler if that fails;
    without ziglang the machine's compiler builds the host's library only. The host's library
    is required (its failure raises); a failing cross target is left out and named in one
    warning line.

    Parameters
    ----------
    sources : Path
        Folder written by :func:`write_sources`.
    staging : Path
        The unpacked FMU; libraries go to ``staging/binaries/<platform>/``.
    identifier : str
        The model identifier (the library's base name).
    fmi_version : int
        2 or 3.
    cross : bool
        Cross-compile for every platform of :data:`~panto.build_fmu.package.PLATFORMS`.

    Returns
    -------
    CompiledBinaries

    Raises
    ------
    CompilationError
        If the host's library does not compile.
    """
    host = host_platform()
    entries = PLATFORMS if cross else (host,) if host is not None else ()
    if find_zig() is None or not entries:
        compile_library(sources, staging / make_binary_path(identifier, fmi_version))
        return CompiledBinaries((host.fmi3_tuple,) if host else (), ())
    built: dict[str, Path] = {}
    failed: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="xc_") as scratch, \
            ThreadPoolExecutor(max_workers=min(len(entries), os.cpu_count() or 1)) as pool:
        jobs = {entry: pool.submit(compile_library, sources, Path(scratch) / entry.fmi3_tuple
                                   / f"{identifier}{entry.extension}",
                                   zig_target=entry.zig_target) for entry in entries}
        for entry, job in jobs.items():
            try:
                built[entry.fmi3_tuple] = job.result()
            except CompilationError as error:
                if entry != host:
                    failed[entry.fmi3_tuple] = _first_message(str(error))
                    continue
                LOGGER.info("zig cc failed for the host, using the native compiler")
                compile_library(sources, staging / make_binary_path(identifier, fmi_version))
        _place_libraries(built, staging, identifier, fmi_version)
    if failed:
        LOGGER.warning("%s (FMI %d.0): no binary for %s (%s)", identifier, fmi_version,
                       ", ".join(failed), "; ".join(sorted(set(failed.values()))))
    return CompiledBinaries(tuple(built) if host is None or host.fmi3_tuple in built else
                            (host.fmi3_tuple, *built), tuple(failed))


def _first_message(text: str) -> str:
    """The first error line of a :class:`CompilationError` text (else its first line)."""
    lines = [line.strip() for line in text.splitlines()[2:] if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    return (errors or lines or text.splitlines())[0]


def _place_libraries(built: dict[str, Path], staging: Path, identifier: str,
                     fmi_version: int) -> None:
    """Copy each built library to its folder; FMI 2.0's darwin64 gets both macOS slices."""
    by_tuple = {entry.fmi3_tuple: entry for entry in PLATFORMS}
    darwin64 = []
    for name, library in built.items():
        entry = by_tuple[name]
        target = platform_binary_path(identifier, fmi_version, entry)
        if fmi_version == 2 and entry.fmi2_folder == "darwin64":
            darwin64.append(library)
        elif target is not None:
            (staging / target).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(library, staging / target)
    if darwin64:
        target = staging / platform_binary_path(identifier, 2, by_tuple["x86_64-darwin"])
        write_universal_library(darwin64, target)


#: Mach-O universal ("fat") header magic and the slice alignment (2**14, arm64's page size).
_FAT_MAGIC = 0xCAFEBABE
_MACHO_MAGIC_64 = 0xFEEDFACF
_FAT_ALIGN = 14


def write_universal_library(slices: list[Path], output: Path) -> Path:
    """Join thin 64-bit Mach-O libraries into one universal (fat) library, as ``lipo`` does.

    Parameters
    ----------
    slices : list of Path
        Thin Mach-O files of different architectures.
    output : Path
        The universal library to write (its folder is created).

    Returns
    -------
    Path
        ``output``.
    """
    blobs = [path.read_bytes() for path in slices]
    header = bytearray(struct.pack(">II", _FAT_MAGIC, len(blobs)))
    body = bytearray()
    offset = len(header) + 20 * len(blobs)
    for blob in blobs:
        magic, cputype, cpusubtype = struct.unpack_from("<IiI", blob)
        if magic != _MACHO_MAGIC_64:
            raise ValueError(f"not a thin 64-bit Mach-O file (magic {magic:#x})")
        start = -(-(offset + len(body)) // 2 ** _FAT_ALIGN) * 2 ** _FAT_ALIGN
        body += bytes(start - offset - len(body)) + blob
        header += struct.pack(">iIIII", cputype, cpusubtype, start, len(blob), _FAT_ALIGN)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_bytes(bytes(header) + bytes(body))
    return output
