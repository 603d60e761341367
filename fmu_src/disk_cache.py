"""The disk cache of derived and compiled models: folder, verified files, keys.

Kept apart from :mod:`~panto.fmu_src.symbolic` so that a process that only reads the cache (the
pantograph at rest in :mod:`panto.identification.structures.linearisation`) never imports SymPy
(a quarter of a second): this module uses the standard library only. The names are re-exported
by :mod:`~panto.fmu_src.symbolic`.
"""
from __future__ import annotations

import hashlib
import os
import sys
import tempfile
from functools import lru_cache
from importlib.metadata import version
from pathlib import Path

#: Environment variable naming the cache folder of derived and compiled models (default
#: ``~/.cache/panto/numeric``).
CACHE_VARIABLE = "PANTO_NUMERIC_CACHE"


def default_cache_dir() -> Path:
    """``$PANTO_NUMERIC_CACHE`` or ``~/.cache/panto/numeric``."""
    return Path(os.environ.get(CACHE_VARIABLE) or Path.home() / ".cache" / "panto" / "numeric")


def read_verified(path: Path) -> bytes | None:
    """Payload of a file written by :func:`write_atomic`; None if missing or corrupted.

    The file is the SHA-256 of the payload followed by the payload.
    """
    try:
        data = path.read_bytes()
    except OSError:
        return None
    return data[32:] if len(data) > 32 and hashlib.sha256(data[32:]).digest() == data[:32] else None


def write_atomic(path: Path, payload: bytes) -> bool:
    """Write ``sha256(payload) + payload`` via a temporary file and a rename.

    Parallel processes (pytest-xdist workers) never see half a file. Returns False, leaving no
    file, if the folder is not writable.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, scratch = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    except OSError:
        return False
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(hashlib.sha256(payload).digest() + payload)
        os.chmod(scratch, 0o644)
        os.replace(scratch, path)
        return True
    except OSError:
        return False
    finally:
        if os.path.exists(scratch):
            os.unlink(scratch)


def prune(folder: Path, pattern: str, keep: int = 4) -> None:
    """Delete all but the ``keep`` newest files matching ``pattern`` (stale source versions).

    A compiled pantograph is 13 MB and every edit of the model sources makes a new one.
    """
    try:
        files = sorted(folder.glob(pattern), key=lambda f: f.stat().st_mtime, reverse=True)
        for stale in files[keep:]:
            stale.unlink(missing_ok=True)
    except OSError:  # another process pruned it first
        pass


@lru_cache(maxsize=1)
def sympy_version() -> str:
    """The installed SymPy's version, read from its package metadata (no import of SymPy)."""
    return version("sympy")


@lru_cache(maxsize=1)
def source_digest() -> str:
    """Hash of the model sources (every ``fmu_src/*.py``), SymPy's and Python's versions."""
    digest = hashlib.sha256(f"{sympy_version()} {sys.version}".encode())
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()[:24]
