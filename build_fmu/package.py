"""Zip an FMU: modelDescription.xml, binaries/<platform>/<identifier>.<ext>, sources/.

The platform table (:data:`PLATFORMS`) names each platform's FMI 2.0 folder, FMI 3.0 tuple,
library extension and ``zig cc`` target.

Entries are written in sorted order with a fixed timestamp, so the same inputs give the same
archive byte for byte.
"""
from __future__ import annotations

import logging
import platform
import zipfile
from dataclasses import dataclass
from pathlib import Path

LOGGER = logging.getLogger(__name__)

_FIXED_TIMESTAMP = (1980, 1, 1, 0, 0, 0)

@dataclass(frozen=True)
class BinaryPlatform:
    """One platform an FMU carries a shared library for.

    Attributes
    ----------
    fmi3_tuple : str
        The FMI 3.0 platform tuple (folder under ``binaries/``), e.g. ``"x86_64-windows"``.
    fmi2_folder : str or None
        The FMI 2.0 platform folder, or None where FMI 2.0 names none (aarch64 Linux; arm64
        macOS goes into the universal ``darwin64`` library).
    extension : str
        The library's file extension (``.so``, ``.dll``, ``.dylib``).
    zig_target : str
        The ``zig cc -target`` triple that cross-compiles for it (Linux: glibc 2.17 baseline).
    host : tuple of str
        ``(platform.system(), platform.machine())`` of a machine of this platform.
    """

    fmi3_tuple: str
    fmi2_folder: str | None
    extension: str
    zig_target: str
    host: tuple[str, str]


#: Every platform the FMUs carry when cross-compiling (``zig cc``), the host's own first on
#: a linux x86-64 machine. FMI 2.0 gets linux64, win64 and a universal (x86_64 + arm64) darwin64.
PLATFORMS = (
    BinaryPlatform("x86_64-linux", "linux64", ".so", "x86_64-linux-gnu.2.17", ("Linux", "x86_64")),
    BinaryPlatform("aarch64-linux", None, ".so", "aarch64-linux-gnu.2.17", ("Linux", "aarch64")),
    BinaryPlatform("x86_64-windows", "win64", ".dll", "x86_64-windows-gnu", ("Windows", "AMD64")),
    BinaryPlatform("x86_64-darwin", "darwin64", ".dylib", "x86_64-macos", ("Darwin", "x86_64")),
    BinaryPlatform("aarch64-darwin", "darwin64", ".dylib", "aarch64-macos", ("Darwin", "arm64")),
)

#: FMI 2.0 folder of a host build without a cross-compiler, where it differs from the table
#: (an aarch64 Linux machine puts its own library into linux64, as fmpy expects there).
_HOST_FMI2_FOLDER = {("Linux", "aarch64"): "linux64"}


def host_platform() -> BinaryPlatform | None:
    """The entry of :data:`PLATFORMS` for this machine, or None if it has none."""
    key = (platform.system(), platform.machine())
    return next((entry for entry in PLATFORMS if entry.host == key), None)


def platform_binary_path(identifier: str, fmi_version: int, entry: BinaryPlatform,
                         *, host_build: bool = False) -> str | None:
    """Path of the library for one platform inside the FMU, or None if FMI 2.0 has no folder.

    Parameters
    ----------
    identifier : str
        The model identifier (the library's base name).
    fmi_version : int
        2 or 3.
    entry : BinaryPlatform
        The platform.
    host_build : bool
        The host's own library built without a cross-compiler (aarch64 Linux then uses
        ``linux64`` for FMI 2.0).

    Returns
    -------
    str or None
        E.g. ``"binaries/win64/Toy.dll"`` (FMI 2) or ``"binaries/x86_64-windows/Toy.dll"``.
    """
    if fmi_version == 2:
        folder = entry.fmi2_folder
        if host_build:
            folder = _HOST_FMI2_FOLDER.get(entry.host, folder)
        if folder is None:
            return None
    else:
        folder = entry.fmi3_tuple
    return f"binaries/{folder}/{identifier}{entry.extension}"


def make_binary_path(identifier: str, fmi_version: int) -> str:
    """Path of the shared library inside the FMU for this machine.

    Parameters
    ----------
    identifier : str
        The model identifier (the library's base name).
    fmi_version : int
        2 or 3.

    Returns
    -------
    str
        E.g. ``"binaries/linux64/Toy.so"`` (FMI 2) or ``"binaries/x86_64-linux/Toy.so"`` (FMI 3).

    Raises
    ------
    RuntimeError
        On a platform this builder does not know.
    """
    entry = host_platform()
    path = None if entry is None else platform_binary_path(identifier, fmi_version, entry,
                                                           host_build=True)
    if path is None:
        key = (platform.system(), platform.machine())
        raise RuntimeError(f"building FMI {fmi_version} FMUs on {key[0]} {key[1]} with the "
                           f"native compiler is not supported (known: "
                           f"{sorted(e.host for e in PLATFORMS)}); install ziglang")
    return path


def fmu_platforms(path: str | Path) -> tuple[str, ...]:
    """The platform folders an FMU carries a binary in (``binaries/<folder>/``), sorted.

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.

    Returns
    -------
    tuple of str
    """
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
    return tuple(sorted({name.split("/")[1] for name in names
                         if name.startswith("binaries/") and name.count("/") >= 2
                         and not name.endswith("/")}))


def package_fmu(staging: Path, destination: Path) -> Path:
    """Zip the content of ``staging`` (an unpacked FMU) into ``destination``.

    Parameters
    ----------
    staging : Path
        Folder holding ``modelDescription.xml``, ``binaries/`` and ``sources/``.
    destination : Path
        The ``.fmu`` file to write (replaced if it exists).

    Returns
    -------
    Path
        ``destination``.
    """
    if not (staging / "modelDescription.xml").is_file():
        raise FileNotFoundError(f"{staging}: no modelDescription.xml to package")
    destination.parent.mkdir(parents=True, exist_ok=True)
    files = sorted(path for path in staging.rglob("*") if path.is_file())
    temporary = destination.with_suffix(destination.suffix + ".partial")
    with zipfile.ZipFile(temporary, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for path in files:
            info = zipfile.ZipInfo(path.relative_to(staging).as_posix(), _FIXED_TIMESTAMP)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, path.read_bytes())
    temporary.replace(destination)
    LOGGER.info("wrote %s (%d files)", destination, len(files))
    return destination
