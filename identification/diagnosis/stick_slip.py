"""The stick-slip recursion of :func:`~panto.identification.diagnosis.augmentations.stick_slip_run`,
compiled.

A discretised linear model ``x[k+1] = Phi x[k] + drive[k] + column f[k]`` with Coulomb friction
``|f| <= level`` on one coordinate is stepped one sample at a time: the friction that would stop
the joint at the end of the step, ``f* = -(drive[k] + Phi x[k])[joint] / column[joint]``, is
applied when ``|f*| <= level`` (the joint sticks), else ``level sign(f*)`` (it slides). The
recursion cannot be vectorised (each step's friction depends on the previous state): the NumPy
loop takes 3.3 ms for a 1449-sample run of the 6-state pantograph, the C kernel of
``stick_slip.c``, with the same arithmetic, 0.09 ms (measured inside the diagnosis, one core).

The kernel is compiled at first use by :mod:`panto.fmu_src.c_kernels` (the system compiler
``$CC``, ``cc`` or ``gcc``, the one the FMUs are built with) into ``$PANTO_KERNEL_CACHE`` or
``~/.cache/panto/kernels/<hash of the source>/`` (a private temporary folder if that cannot be
written), built under a temporary name and renamed into place, so parallel test workers never load
half a file. Without a compiler, or if building or loading fails, the NumPy loop runs instead,
silently; :func:`active_backend` tells which path runs. :data:`USE_COMPILED` ``= False`` or
``PANTO_STICK_SLIP_KERNEL=0`` forces the NumPy loop.
"""
from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import numpy as np

from panto.fmu_src import c_kernels

#: The C source of the kernel (shipped as package data).
SOURCE = Path(__file__).with_name("stick_slip.c")
#: Flags of the build: ISO C, no fused multiply-adds (the products round as NumPy's do).
COMPILER_FLAGS = ("-std=c99", "-O2", "-ffp-contract=off")
#: Environment variable: ``0`` switches the compiled kernel off (the NumPy loop).
SWITCH_VARIABLE = "PANTO_STICK_SLIP_KERNEL"
#: False forces the NumPy loop (the compiled kernel is then neither built nor loaded).
USE_COMPILED = True


def _compiler() -> str | None:
    return c_kernels.find_compiler()


def _bind(library: ctypes.CDLL) -> ctypes._CFuncPtr:
    """The kernel's entry point in `library`, typed."""
    function = library.stick_slip_step
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_size_t] * 3 + [ctypes.c_double] * 2
    return function


#: How the kernel is built, typed and switched (:class:`panto.fmu_src.c_kernels.Kernel`).
BUILD = c_kernels.Kernel("stick_slip", SWITCH_VARIABLE, COMPILER_FLAGS, SOURCE, _bind,
                         find=lambda: _compiler())


@functools.lru_cache(maxsize=1)
def load_kernel() -> ctypes._CFuncPtr | None:
    """The compiled kernel (built on the first call into the kernel cache, else into a private
    temporary folder), or None where it cannot be built or loaded."""
    return BUILD.load()


def active_backend() -> str:
    """``"compiled"`` when :func:`run_stick_slip` runs the C kernel, else ``"numpy"``."""
    return "compiled" if _use_kernel() is not None else "numpy"


def _use_kernel() -> ctypes._CFuncPtr | None:
    """The kernel when it is switched on and available, else None."""
    return load_kernel() if USE_COMPILED and BUILD.enabled() else None


def run_stick_slip(phi: np.ndarray, drive: np.ndarray, x_start: np.ndarray, column: np.ndarray,
                   joint: int, level: float) -> np.ndarray:
    """States of ``x[k+1] = Phi x[k] + drive[k] + column f[k]`` with Coulomb friction
    ``|f[k]| <= level`` on state `joint` (module notes), shape ``(len(drive) + 1, n)``.

    Parameters
    ----------
    phi : ndarray, shape (n, n)
        Transition matrix over one sample period [-].
    drive : ndarray, shape (N, n)
        The inputs' contribution to each step, in the units of the states.
    x_start : ndarray, shape (n,)
        State at the first sample.
    column : ndarray, shape (n,)
        Response of the states over one step to a unit friction held over the step (the units of
        the states per unit of `level`); ``column[joint]`` is the gain ``Gamma_a`` of the joint's
        velocity (0: no friction is applied).
    joint : int
        Index of the state on which the friction acts (a velocity).
    level : float
        Friction level ``|f| <= level``, in the units of the input behind `column` (e.g. [bar]).

    Returns
    -------
    ndarray, shape (N + 1, n)
        The states; NaN or inf in the inputs propagate as in IEEE arithmetic (no warnings).
    """
    states = np.empty((len(drive) + 1, len(x_start)))
    states[0], states[1:] = x_start, drive
    phi, column = (np.ascontiguousarray(a, dtype=float) for a in (phi, column))
    n = states.shape[1]
    if phi.shape != (n, n) or column.shape != (n,) or not 0 <= joint < n:
        raise ValueError(f"phi {phi.shape}, column {column.shape} and joint {joint} do not "
                         f"match {n} states")
    kernel = _use_kernel()
    if kernel is None:
        return _step_numpy(states, phi, column, joint, float(level))
    kernel(states.ctypes.data, phi.ctypes.data, column.ctypes.data, states.shape[0],
           states.shape[1], joint, float(column[joint]), float(level))
    return states


def _step_numpy(states: np.ndarray, phi: np.ndarray, column: np.ndarray, joint: int,
                level: float) -> np.ndarray:
    """The NumPy loop over `states` (row 0 the start, row k + 1 ``drive[k]`` on entry), in place:
    the reference the kernel reproduces. A NaN ``f*`` gives ``-level`` (Python's min/max)."""
    gain = float(column[joint])
    rows, product, kick = list(states), np.empty(states.shape[1]), np.empty(states.shape[1])
    with np.errstate(over="ignore", invalid="ignore"):
        for x, row in zip(rows, rows[1:]):  # row: drive[k] + Phi x[k] (free), then + friction
            np.add(row, np.matmul(phi, x, out=product), out=row)
            f = -float(row[joint]) / gain if gain != 0.0 else 0.0
            np.add(row, np.multiply(column, min(level, max(-level, f)), out=kick), out=row)
    return states


__all__ = ["run_stick_slip", "active_backend", "load_kernel", "USE_COMPILED", "SWITCH_VARIABLE",
           "SOURCE", "COMPILER_FLAGS", "BUILD"]
