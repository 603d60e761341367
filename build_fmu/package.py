"""Zip an FMU: modelDescription.xml, binaries/<platform>/<identifier>.<ext>, sources/.

Entries are written in sorted order with a fixed timestamp, so the same inputs give the same
archive byte for byte.
"""
from __future__ import annotations

import logging
import platform
import zipfile
from pathlib import Path

LOGGER = logging.getLogger(__name__)

_FIXED_TIMESTAMP = (1980, 1, 1, 0, 0, 0)

#: (system, machine) → (FMI 2.0 platform folder, FMI 3.0 platform tuple, library extension)
_PLATFORMS = {
    ("Linux", "x86_64"): ("linux64", "x86_64-linux", ".so"),
    ("Linux", "aarch64"): ("linux64", "aarch64-linux", ".so"),
    ("Darwin", "x86_64"): ("darwin64", "x86_64-darwin", ".dylib"),
    ("Darwin", "arm64"): ("darwin64", "aarch64-darwin", ".dylib"),
}


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
    key = (platform.system(), platform.machine())
    if key not in _PLATFORMS:
        raise RuntimeError(f"building FMUs on {key[0]} {key[1]} is not supported "
                           f"(known: {sorted(_PLATFORMS)})")
    fmi2_folder, fmi3_folder, extension = _PLATFORMS[key]
    folder = fmi2_folder if fmi_version == 2 else fmi3_folder
    return f"binaries/{folder}/{identifier}{extension}"


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
