"""Small C kernels compiled at run time and cached by the hash of their source.

The catenary step (:mod:`panto.catenary_cosim.kernel`), the co-simulation loop and the friction
oscillators' splitting loop (:mod:`panto.identification.structures.friction_kernel`) are plain
C99 compiled with the system compiler (``$CC``, ``cc`` or ``gcc``) into
``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<first 12 hex of the source's SHA-256>/``
the first time they are needed, built in a temporary file and moved into place so that parallel
workers never load half a file; where the cache cannot be written, into a private temporary
folder. Without a compiler :func:`build_library` gives None and the callers keep their Python
path.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Callable

#: Environment variable naming the kernel cache folder (default ``~/.cache/panto/kernels``).
CACHE_VARIABLE = "PANTO_KERNEL_CACHE"


def switched_on(variable: str) -> bool:
    """False when the environment variable `variable` is ``0`` (or ``false``/``no``/``off``)."""
    return os.environ.get(variable, "1").strip().lower() not in ("0", "false", "no", "off")


def find_compiler() -> str | None:
    """The first of ``$CC``, ``cc``, ``gcc`` on the path, or None."""
    for candidate in (os.environ.get("CC"), "cc", "gcc"):
        if candidate and shutil.which(candidate):
            return candidate
    return None


def cache_folder(source: str) -> Path:
    """The cache folder of the C `source` (its hash under the kernel cache)."""
    base = os.environ.get(CACHE_VARIABLE) or Path.home() / ".cache" / "panto" / "kernels"
    return Path(base) / hashlib.sha256(source.encode()).hexdigest()[:12]


def build(target: Path, source: str, flags: tuple[str, ...], compiler: str | None) -> None:
    """Compile `source` with `flags` into the shared library `target` (atomically); OSError when
    there is no compiler, CalledProcessError when it fails."""
    if compiler is None:
        raise OSError("no C compiler ($CC, cc, gcc)")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as scratch:
        path = Path(scratch) / f"{target.stem}.c"
        path.write_text(source)
        built = Path(scratch) / target.name
        subprocess.run([compiler, *flags, "-fPIC", "-shared", "-o", str(built), str(path), "-lm"],
                       check=True, capture_output=True, timeout=120)
        os.replace(built, target)


def build_library(source: str, name: str, flags: tuple[str, ...] = ("-O2",),
                  find: Callable[[], str | None] = find_compiler) -> ctypes.CDLL | None:
    """The shared library ``name.so`` compiled from `source` (cached, built on first use with the
    compiler `find` names; in a private temporary folder when the cache cannot be written), or
    None if it cannot be built."""
    target = cache_folder(source) / f"{name}.so"
    try:
        if not target.exists():
            compiler = find()
            try:
                build(target, source, flags, compiler)
            except OSError:
                if compiler is None:
                    raise
                target = Path(tempfile.mkdtemp(prefix="panto-kernel-")) / f"{name}.so"
                build(target, source, flags, compiler)
        return ctypes.CDLL(str(target))
    except (OSError, subprocess.SubprocessError):
        return None


__all__ = ["CACHE_VARIABLE", "switched_on", "find_compiler", "cache_folder", "build",
           "build_library"]
