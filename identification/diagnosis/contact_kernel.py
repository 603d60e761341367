"""The unilateral contact's switched recursion, compiled.

:func:`~panto.identification.diagnosis.unilateral_contact.simulate_switched` runs the model in
contact over the whole record with NumPy, then, from the first sample where the contact force
changes sign, the switched recursion: stretches of whole samples, each checked at its sub-step
instants, and the samples with a switch sub-step by sub-step (``_run_switched`` and ``_within``
of that module). That recursion is a Python loop with some 60 switches in a 60 s rig run; in C
(``contact_kernel.c``) it is the same algorithm with the same operations (the same stretches,
the same products and sums in the same places), fed the exponential tables the NumPy code
prepares; the flight's per-sample tables (``offsets``, ``drive``) only for the samples it
visits in flight. The run in contact is the recursion ``x[k+1] = Phi x[k] + drive[k]`` sample by
sample (:func:`propagate`) where the NumPy path filters it in modal coordinates. The summation
order inside the small matrix products differs from NumPy's (BLAS kernels sum in their own
order, with fused multiply-adds), and the two contact runs differ by rounding: the states agree
to ~1e-13 of their range, not bit for bit (``tests/test_contact_kernel.py`` states the
tolerance). Measured on the 80 runs of a 60 s, 3050-sample rig record around the diagnosis
speed benchmark's accepted contact-loss fit (12 % of the time in flight, ~60 switches): 1.55 ms
per :func:`~panto.identification.diagnosis.unilateral_contact.simulate_switched` call against
5.2-6.2 ms with the NumPy loop (one core), the states within 6e-14 of their size.

The kernel is compiled at first use by :mod:`panto.fmu_src.c_kernels` (``$CC``, ``cc`` or
``gcc``) into ``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<hash of the source>/``.
Without a compiler, or if building or loading fails, the NumPy loop runs instead, silently;
:func:`active_backend` tells which path runs. :data:`USE_COMPILED` ``= False`` or
``PANTO_CONTACT_KERNEL=0`` forces the NumPy loop.
"""
from __future__ import annotations

import ctypes
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from panto.fmu_src import c_kernels

#: The C source of the kernel (shipped as package data).
SOURCE = Path(__file__).with_name("contact_kernel.c")
#: Flags of the build: ISO C, no fused multiply-adds, libm's ``pow`` kept as a call; ``-O3``
#: vectorises the force check across the sub-step instants (element-wise, the same roundings).
COMPILER_FLAGS = ("-std=c99", "-O3", "-ffp-contract=off", "-fno-builtin")
#: Environment variable: ``0`` switches the compiled kernel off (the NumPy loop).
SWITCH_VARIABLE = "PANTO_CONTACT_KERNEL"
#: False forces the NumPy loop (the compiled kernel is then neither built nor loaded).
USE_COMPILED = True
#: Tables of a mode the kernel reads, in its order (attributes of the contact module's modes).
TABLES = ("maps", "rows", "rows_x", "offsets", "drive", "kick")


@dataclass(frozen=True)
class Kernel:
    """The kernel's entry points, typed."""

    switched: ctypes._CFuncPtr
    """``contact_switched``: the switched recursion."""
    propagate: ctypes._CFuncPtr
    """``contact_propagate``: the run in contact."""


def _bind(library: ctypes.CDLL) -> Kernel:
    """The kernel's entry points in `library`, typed."""
    switched = library.contact_switched
    switched.restype = ctypes.c_int
    switched.argtypes = ([ctypes.c_void_p] * 4 + [ctypes.c_size_t] * 5 + [ctypes.c_void_p] * 2
                         + [ctypes.c_double, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p,
                            ctypes.c_size_t, ctypes.c_void_p])
    propagate = library.contact_propagate
    propagate.restype = None
    propagate.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_size_t] * 2
    return Kernel(switched, propagate)


#: How the kernel is built, typed and switched (:class:`panto.fmu_src.c_kernels.Kernel`).
BUILD = c_kernels.Kernel("contact_kernel", SWITCH_VARIABLE, COMPILER_FLAGS, SOURCE, _bind,
                         find=lambda: c_kernels.find_compiler())


@functools.lru_cache(maxsize=1)
def load_kernel() -> Kernel | None:
    """The compiled kernel (built on the first call into the kernel cache, else into a private
    temporary folder), or None where it cannot be built or loaded."""
    return BUILD.load()


def _use_kernel() -> Kernel | None:
    """The kernel when it is switched on and available, else None."""
    return load_kernel() if USE_COMPILED and BUILD.enabled() else None


def active_backend() -> str:
    """``"compiled"`` when :func:`run_switched` runs the C kernel, else ``"numpy"``."""
    return "compiled" if _use_kernel() is not None else "numpy"


def propagate(phi: np.ndarray, drive: np.ndarray, x0: np.ndarray) -> np.ndarray | None:
    """States of ``x[k+1] = Phi x[k] + drive[k]`` from `x0` sample by sample in C, shape
    ``(len(drive) + 1, n)`` (units of the states), or None when the kernel is off or unavailable
    (then :func:`panto.identification.structures.linearisation.propagate`, the same recursion
    in modal coordinates, to rounding)."""
    kernel = _use_kernel()
    if kernel is None:
        return None
    phi, drive = _contiguous(phi), _contiguous(drive)
    states = np.empty((len(drive) + 1, len(x0)))
    states[0] = x0
    if phi.shape != (states.shape[1],) * 2 or drive.shape[1:] != (states.shape[1],):
        raise ValueError(f"phi {phi.shape} and drive {drive.shape} do not match "
                         f"{states.shape[1]} states")
    kernel.propagate(states.ctypes.data, phi.ctypes.data, drive.ctypes.data, len(states),
                     states.shape[1])
    return states


def _check_shapes(modes: list, states: np.ndarray, u: np.ndarray, slope: np.ndarray, start: int,
                  c_force: np.ndarray, d_force: np.ndarray,
                  powers: tuple[np.ndarray, np.ndarray]) -> None:
    """Refuse arrays whose shapes do not fit each other (the C code reads them unchecked)."""
    (count, n), m = states.shape, u.shape[1]
    substeps = modes[0].rows.shape[0]
    expected = {"u": (u.shape, (count, m)), "slope": (slope.shape, (count - 1, m)),
                "c_force": (np.shape(c_force), (n,)), "d_force": (np.shape(d_force), (m,))}
    for index, power in enumerate(powers):
        expected[f"powers[{index}]"] = (power.shape, (len(power), n, n))
    for index, mode in enumerate(modes):
        shapes = {"maps": (substeps, n, n + 2 * m), "rows": (substeps, n + 2 * m),
                  "rows_x": (substeps, n), "offsets": (count - 1, substeps),
                  "drive": (count - 1, n), "kick": (n, 2)}
        expected.update({f"mode {index} {name}": (getattr(mode, name).shape, shape)
                         for name, shape in shapes.items() if getattr(mode, name) is not None})
    wrong = [f"{name} {got} (expected {want})" for name, (got, want) in expected.items()
             if tuple(got) != tuple(want)]
    if len(modes) != 2 or not 0 <= int(start) < count - 1 or wrong:
        raise ValueError(f"unilateral contact kernel: {len(modes)} modes, start {start} of "
                         f"{count} samples; " + "; ".join(wrong))


def _contiguous(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=float)


def run_switched(modes: list, states: np.ndarray, u: np.ndarray, slope: np.ndarray, start: int,
                 c_force: np.ndarray, d_force: np.ndarray, h: float,
                 powers: tuple[np.ndarray, np.ndarray]) -> bool:
    """The switched recursion in C, in place of the NumPy ``_run_switched`` (module notes).

    Parameters
    ----------
    modes : list of the contact module's ``_Mode``
        In contact and in flight, with the tables :data:`TABLES` (``offsets`` and ``drive`` may
        be None: the kernel then computes the rows it needs).
    states : ndarray, shape (N, n), C-contiguous float
        The run in contact on entry; rows ``start + 1`` on overwritten (units of the states).
    u, slope : ndarray, shape (N, m) and (N - 1, m)
        Inputs and their slopes per second.
    start : int
        Sample from which the recursion runs.
    c_force, d_force : ndarray
        Rows of the contact force [N per unit of state / input].
    h : float
        Sub-step [s].
    powers : (ndarray, ndarray)
        ``Phi^j`` in contact and in flight, ``j = 0..stretch`` and ``0..flight stretch``.

    Returns
    -------
    bool
        False when the kernel is off or unavailable (`states` untouched): run the NumPy loop.
    """
    kernel = _use_kernel()
    if kernel is None:
        return False
    if not (states.flags.c_contiguous and states.dtype == float):
        raise ValueError("unilateral contact kernel: the states must be C-contiguous floats")
    _check_shapes(modes, states, u, slope, start, c_force, d_force, powers)
    arrays = [getattr(mode, name) for mode in modes for name in TABLES]
    arrays = [None if a is None else _contiguous(a.T if name == "rows_x" else a)
              for a, name in zip(arrays, TABLES * len(modes))]
    pointers = (ctypes.c_void_p * len(arrays))(*(None if a is None else a.ctypes.data
                                                 for a in arrays))
    bilateral = states.copy()
    u, slope, c_force, d_force = (_contiguous(a) for a in (u, slope, c_force, d_force))
    contact, flight = (_contiguous(p) for p in powers)
    n, m = states.shape[1], u.shape[1]
    status = kernel.switched(states.ctypes.data, bilateral.ctypes.data, u.ctypes.data,
                             slope.ctypes.data, len(states), n, m, modes[0].rows.shape[0],
                             int(start), c_force.ctypes.data, d_force.ctypes.data, float(h),
                             contact.ctypes.data, len(contact) - 1, flight.ctypes.data,
                             len(flight) - 1, pointers)
    if status != 0:
        raise MemoryError("unilateral contact kernel: no workspace")
    return True


__all__ = ["run_switched", "propagate", "Kernel", "active_backend", "load_kernel", "USE_COMPILED",
           "SWITCH_VARIABLE", "SOURCE", "COMPILER_FLAGS", "TABLES", "BUILD"]
