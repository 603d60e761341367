"""Small C kernels compiled at run time and cached by the hash of their source and flags.

The catenary step (:mod:`panto.catenary_cosim.kernel`), the co-simulation loop and the friction
oscillators' splitting loop (:mod:`panto.identification.structures.friction_kernel`) are plain
C99 compiled with the system compiler (``$CC``, ``cc`` or ``gcc``) into
``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<first 12 hex of the SHA-256 of source and
flags>/`` the first time they are needed, built in a temporary file and moved into place so
that parallel workers never load half a file; where the cache cannot be written, into a
private temporary folder. Without a compiler :func:`build_library` gives None and the callers
keep their Python path. A :class:`Kernel` names one kernel's library, source, flags,
environment switch and ctypes typing, so that each calling module keeps only its cached
``load_kernel``-style function.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

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


def cache_folder(source: str, flags: tuple[str, ...] | None = None) -> Path:
    """The cache folder of the C `source` built with `flags` (their hash under the kernel cache:
    a changed flag, such as the ``-ffp-contract=off`` a bit-for-bit kernel rests on, never meets
    a library built without it)."""
    base = os.environ.get(CACHE_VARIABLE) or Path.home() / ".cache" / "panto" / "kernels"
    text = source if flags is None else source + "\0" + "\0".join(flags)
    return Path(base) / hashlib.sha256(text.encode()).hexdigest()[:12]


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
    target = cache_folder(source, flags) / f"{name}.so"
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


def _untyped(library: ctypes.CDLL) -> ctypes.CDLL:
    return library


@dataclass(frozen=True)
class Kernel:
    """One compiled kernel: its library's name, environment switch, flags, C source and typing.

    The caller caches :meth:`load` once per process (``functools.lru_cache`` on a module
    function, which tests clear) and checks :meth:`enabled` before using it.
    """

    name: str
    """Stem of the shared library (``<name>.so`` in the source's cache folder)."""
    variable: str
    """Environment variable whose ``0`` (``false``/``no``/``off``) switches the kernel off."""
    flags: tuple[str, ...] = ("-O2",)
    """Compiler flags (``-fPIC -shared`` and ``-lm`` are added)."""
    source: str | Path | None = None
    """The C source, or the file holding it (read at each :meth:`load`); None: given per call."""
    bind: Callable[[ctypes.CDLL], Any] = _untyped
    """Types the entry points of a loaded library and gives what :meth:`load` returns."""
    find: Callable[[], str | None] = find_compiler
    """Names the compiler (None: none); a lambda looks a patched finder up at call time."""

    def enabled(self) -> bool:
        """False when the environment switch :attr:`variable` is ``0`` (see :func:`switched_on`)."""
        return switched_on(self.variable)

    def load(self, source: str | None = None,
             bind: Callable[[ctypes.CDLL], Any] | None = None) -> Any | None:
        """The library built from `source` (default :attr:`source`) and typed by `bind` (default
        :attr:`bind`), or None where the source cannot be read, the library cannot be built or
        loaded, or it lacks an entry point (not our library). Not cached."""
        try:
            if source is None:
                if self.source is None:
                    return None
                source = self.source if isinstance(self.source, str) else \
                    self.source.read_text(encoding="utf-8")
        except OSError:
            return None
        library = build_library(source, self.name, self.flags, find=self.find)
        try:
            return None if library is None else (bind or self.bind)(library)
        except AttributeError:  # not our library
            return None


__all__ = ["CACHE_VARIABLE", "switched_on", "find_compiler", "cache_folder", "build",
           "build_library", "Kernel"]
