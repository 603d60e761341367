"""The friction oscillators' stick-slip integration as a small compiled kernel (C, cached).

:func:`panto.identification.structures.oscillators.OscillatorStructure.simulate` with Coulomb
friction runs ``substeps`` Strang-splitting sub-steps per sample (module notes there): per
sub-step one product with the exact linear flow ``Phi`` (2n x 2n, n = 2 or 3 masses) and the
closed-form friction flow ``v + v_eps (asinh(q sinh(v / v_eps)) - v / v_eps)`` per mass
(``q = exp(-F_f t / (m v_eps))``). In Python that is some 7 µs of interpreter per sub-step (one
second of CPU for three minutes of data at 50 Hz, 16 sub-steps: 144 000 sub-steps); the same
loop in C takes about 0.1 µs.

:func:`friction_run` does what the reference loop :func:`friction_loop` (Python, kept as the
reference and the fallback) does, step for step: ``x <- Phi x + drive[j]``, then
``a = clip(x_v / v_eps, -700, 700)``, the state at every `substeps`-th sub-step recorded with
the half step ``q = half`` applied, then the merged full step ``q = full``. The one difference
is how the closed form is evaluated: with ``w = exp(-2 |a|)``,
``asinh(q sinh a) - a = sign(a) log(q (1 - w) / 2 + sqrt((q (1 - w) / 2)^2 + w))`` for
``|a| <= 20`` (the same function, one exp, one sqrt and one log instead of a sinh and an
asinh); beyond, ``sinh |a| = e^|a| / 2`` to rounding and it is ``asinh(e^s / 2) - |a|``,
``s = |a| + log q``, which is ``log q`` to below the rounding of ``a`` once ``s > 20``. Both paths give the same states to round-off
(the tests compare them to 1e-12).

The source is compiled with the system C compiler (``$CC``, ``cc`` or ``gcc``) into
``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<hash of the source>/`` the first time it is
needed (about 0.2 s), built in a temporary file and moved into place so that parallel workers
never load half a file. Without a compiler, or with ``PANTO_FRICTION_KERNEL=0``, the oscillator
keeps the Python loop.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np

from panto.fmu_src import c_kernels

#: Environment variable: ``0`` switches the compiled kernel off (the Python loop).
SWITCH_VARIABLE = "PANTO_FRICTION_KERNEL"
#: Environment variable naming the kernel cache folder (default ``~/.cache/panto/kernels``).
CACHE_VARIABLE = c_kernels.CACHE_VARIABLE

C_SOURCE = r"""
/* The friction oscillators' Strang-splitting loop (panto.identification.structures.friction_kernel).
   State x = [z; v] of size 2 n; phi row-major (2n x 2n); drive (steps x 2n); states
   (steps / substeps + 1) x 2n, row 0 already filled by the caller. x holds the state after the
   leading half step of friction and is advanced in place. */
#include <math.h>

/* Velocity change, in units of v_eps, of the friction flow started at a = v / v_eps with the
   factor q = exp(-F_f t / (m v_eps)) (log_q its logarithm): asinh(q sinh a) - a, odd in a.
   For |a| <= 20, with w = exp(-2 |a|) and w0 = 1 - w (each computed from the other where it
   is the larger, so neither cancels):
   q sinh|a| / e^|a| = q w0 / 2 =: h and sqrt(q^2 sinh^2 a + 1) / e^|a| = sqrt(h^2 + w), so it
   is log(h + sqrt(h^2 + w)): one exp, one sqrt, one log. Beyond |a| = 20, sinh|a| = e^|a| / 2
   to rounding: asinh(e^s / 2) - |a| with s = |a| + log q, which is log q (to below the rounding
   of a) once s > 20. */
static double flow(double a, double q, double log_q, double w, double w0)
{
    double magnitude = fabs(a), h, d, s;
    if (magnitude <= 20.0) {
        h = 0.5 * q * w0;
        d = log(h + sqrt(h * h + w));
    } else {
        s = magnitude + log_q;
        d = s > 20.0 ? log_q : asinh(0.5 * exp(s)) - magnitude;
    }
    return a < 0.0 ? -d : d;
}

void friction_run(int n, long steps, int substeps, const double *phi, const double *drive,
                  double *x, const double *half, const double *full, double v_eps,
                  double *states)
{
    const int m = 2 * n;
    const double inverse = 1.0 / v_eps;
    double next[6], v[3], w[3], w0[3], log_half[3], log_full[3];
    long step;
    int i, k;
    for (i = 0; i < n; i++) {
        log_half[i] = log(half[i]);
        log_full[i] = log(full[i]);
    }
    for (step = 0; step < steps; step++) {
        const double *d = drive + (long)m * step;
        for (i = 0; i < m; i++) {
            const double *row = phi + (long)m * i;
            double y = 0.0;
            for (k = 0; k < m; k++) y += row[k] * x[k];
            next[i] = y + d[i];
        }
        for (i = 0; i < m; i++) x[i] = next[i];
        for (i = 0; i < n; i++) {
            double a = x[n + i] * inverse, magnitude;
            v[i] = a < -700.0 ? -700.0 : (a > 700.0 ? 700.0 : a);
            magnitude = fabs(v[i]);
            if (magnitude < 0.35) {  /* w >= 1/2: w0 accurately by expm1, then w */
                w0[i] = -expm1(-2.0 * magnitude);
                w[i] = 1.0 - w0[i];
            } else {  /* w < 1/2: w accurately (tiny for large |a|), then w0 */
                w[i] = exp(-2.0 * magnitude);
                w0[i] = 1.0 - w[i];
            }
        }
        if ((step + 1) % substeps == 0) {
            double *out = states + (long)m * ((step + 1) / substeps);
            for (i = 0; i < n; i++) {
                out[i] = x[i];
                out[n + i] = x[n + i] + v_eps * flow(v[i], half[i], log_half[i], w[i], w0[i]);
            }
        }
        for (i = 0; i < n; i++)
            x[n + i] += v_eps * flow(v[i], full[i], log_full[i], w[i], w0[i]);
    }
}

/* The nonlinear oscillators' Strang-splitting loop (panto.identification.structures.
   oscillator_effects): per sub-step half a kick of the nonlinear springs and half a friction flow,
   the exact linear flow, the other halves; the state recorded every `substeps` sub-steps.
   x = [z; v] (2 n); phi row-major (2n x 2n); drive (steps x 2n); states row 0 filled by the
   caller; decay[i] = F_f,i h / (2 m_i v_eps); kick[i] = h / (2 m_i); springs[i] = k_i kc_i;
   quadratic[i] = k_i kq_i; centre[i] the spring's deflection at the operating point; the
   spring's extra tension is (quadratic + springs d) d d for its deflection d from there. */
static void nonlinear_half(int n, double *x, const double *decay, double v_eps,
                           const double *springs, const double *quadratic,
                           const double *centre, const double *kick, int friction_first)
{
    double tension[3];
    int i;
    if (!friction_first) {
        for (i = 0; i < n; i++) {
            double d = x[i] - (i ? x[i - 1] : 0.0) - centre[i];
            tension[i] = (quadratic[i] + springs[i] * d) * d * d;
        }
        for (i = 0; i < n; i++)
            x[n + i] += kick[i] * (-tension[i] + (i + 1 < n ? tension[i + 1] : 0.0));
    }
    for (i = 0; i < n; i++) {
        if (decay[i] > 0.0) {
            double a = x[n + i] / v_eps;
            if (a > 700.0) a = 700.0;
            if (a < -700.0) a = -700.0;
            x[n + i] += v_eps * (asinh(sinh(a) * exp(-decay[i])) - a);
        }
    }
    if (friction_first) {
        for (i = 0; i < n; i++) {
            double d = x[i] - (i ? x[i - 1] : 0.0) - centre[i];
            tension[i] = (quadratic[i] + springs[i] * d) * d * d;
        }
        for (i = 0; i < n; i++)
            x[n + i] += kick[i] * (-tension[i] + (i + 1 < n ? tension[i + 1] : 0.0));
    }
}

int nonlinear_run(int n, long steps, int substeps, const double *phi, const double *drive,
                  double *x, const double *decay, double v_eps, const double *springs,
                  const double *quadratic, const double *centre, const double *kick,
                  double *states)
{
    const int m = 2 * n;
    double next[6];
    long step;
    int i, k;
    for (step = 0; step < steps; step++) {
        const double *d = drive + (long)m * step;
        nonlinear_half(n, x, decay, v_eps, springs, quadratic, centre, kick, 0);
        for (i = 0; i < m; i++) {
            const double *row = phi + (long)m * i;
            double y = d[i];
            for (k = 0; k < m; k++) y += row[k] * x[k];
            next[i] = y;
        }
        for (i = 0; i < m; i++) x[i] = next[i];
        nonlinear_half(n, x, decay, v_eps, springs, quadratic, centre, kick, 1);
        for (i = 0; i < m; i++)
            if (!isfinite(x[i])) return -1;
        if ((step + 1) % substeps == 0) {
            double *out = states + (long)m * ((step + 1) / substeps);
            for (i = 0; i < m; i++) out[i] = x[i];
        }
    }
    return 0;
}
"""

_POINTER = ctypes.c_void_p
#: Largest number of masses the kernel's stack arrays hold.
MAX_MASSES = 3


def enabled() -> bool:
    """False when ``$PANTO_FRICTION_KERNEL`` is ``0`` (or ``false``/``no``/``off``)."""
    return BUILD.enabled()


def _compiler() -> str | None:
    return c_kernels.find_compiler()


def _declare(library: ctypes.CDLL) -> ctypes.CDLL:
    """`library` with the argument and result types of ``friction_run`` and ``nonlinear_run``."""
    library.friction_run.restype = None
    library.friction_run.argtypes = [ctypes.c_int, ctypes.c_long, ctypes.c_int] + [_POINTER] * 5 \
        + [ctypes.c_double, _POINTER]
    library.nonlinear_run.restype = ctypes.c_int
    library.nonlinear_run.argtypes = [ctypes.c_int, ctypes.c_long, ctypes.c_int] + [_POINTER] * 4 \
        + [ctypes.c_double] + [_POINTER] * 5
    return library


#: How the kernel is built, typed and switched (:class:`panto.fmu_src.c_kernels.Kernel`; no fused
#: multiply-adds, so the products round as NumPy's do).
BUILD = c_kernels.Kernel("friction_run", SWITCH_VARIABLE, ("-O2", "-ffp-contract=off"), C_SOURCE,
                         _declare, find=lambda: _compiler())


@lru_cache(maxsize=1)
def load_library() -> ctypes.CDLL | None:
    """The compiled kernel (built into the cache on first use: :mod:`panto.fmu_src.c_kernels`),
    or None if it cannot be built."""
    return BUILD.load()


def available() -> bool:
    """True when the kernel is switched on and could be built and loaded."""
    return enabled() and load_library() is not None


def friction_run(phi: np.ndarray, drive: np.ndarray, x: np.ndarray, substeps: int,
                 half: np.ndarray, full: np.ndarray, v_eps: float, states: np.ndarray) -> None:
    """Run the sub-steps in C, filling ``states[1:]`` (see the module notes).

    Parameters
    ----------
    phi : ndarray, shape (2n, 2n)
        Exact linear flow over one sub-step.
    drive : ndarray, shape (steps, 2n)
        Input contribution of every sub-step (``steps`` a multiple of `substeps`).
    x : ndarray, shape (2n,)
        State after the leading friction half step ([m], [m/s]); advanced in place.
    substeps : int
        Sub-steps per sample.
    half, full : ndarray, shape (n,)
        ``exp(-F_f h / (2 m v_eps))`` and its square (h the sub-step [s]).
    v_eps : float
        Friction smoothing velocity [m/s].
    states : ndarray, shape (steps / substeps + 1, 2n)
        Output; row 0 is left as it is.

    Raises
    ------
    OSError
        If the kernel is not available.
    """
    library, arrays = _checked(x, states, substeps, phi, drive, half, full)
    n = len(half)
    library.friction_run(n, arrays[1].shape[0], int(substeps),
                         *(a.ctypes.data for a in arrays[:2]), x.ctypes.data,
                         *(a.ctypes.data for a in arrays[2:]), float(v_eps), states.ctypes.data)


def _checked(x: np.ndarray, states: np.ndarray, substeps: int, phi: np.ndarray,
             drive: np.ndarray, per_mass: np.ndarray, *more: np.ndarray
             ) -> tuple[ctypes.CDLL, list[np.ndarray]]:
    """The loaded kernel and ``(phi, drive, per_mass, *more)`` as contiguous float64 arrays, after
    the checks both entry points share (the masses, the in-place buffers, the sub-step count)."""
    library = load_library()
    if library is None:
        raise OSError("the friction kernel could not be built (no C compiler?)")
    n = len(per_mass)
    if not 1 <= n <= MAX_MASSES:
        raise ValueError(f"the friction kernel takes 1 to {MAX_MASSES} masses, not {n}")
    arrays = [np.ascontiguousarray(a, dtype=float) for a in (phi, drive, per_mass, *more)]
    for array, name in ((x, "x"), (states, "states")):
        if array.dtype != np.float64 or not array.flags.c_contiguous:
            raise ValueError(f"{name} must be a C-contiguous float64 array")
    if arrays[1].shape[0] % substeps or states.shape[0] != arrays[1].shape[0] // substeps + 1:
        raise ValueError("drive and states do not match the number of sub-steps")
    return library, arrays


def nonlinear_run(phi: np.ndarray, drive: np.ndarray, x: np.ndarray, substeps: int,
                  decay: np.ndarray, v_eps: float, springs: np.ndarray, quadratic: np.ndarray,
                  centre: np.ndarray, kick: np.ndarray, states: np.ndarray) -> None:
    """The nonlinear oscillators' splitting loop in C, filling ``states[1:]``
    (:mod:`~panto.identification.structures.oscillator_effects`, whose Python loop is the reference).

    Per sub-step: half a kick of the nonlinear springs, half a friction flow, the exact linear
    flow (``Phi``, `drive`), the friction half, the kick half; ``decay[i] = F_f,i h / (2 m_i
    v_eps)``, ``kick[i] = h / (2 m_i)`` [s/kg], ``springs[i] = k_i kc_i`` [N/m^3],
    ``quadratic[i] = k_i kq_i`` [N/m^2], ``centre[i]`` the spring's deflection at the operating
    point [m] (a spring's extra tension ``(quadratic + springs d) d^2`` for its deflection ``d``
    from there). `x` [m, m/s] is advanced in place.

    Raises
    ------
    OSError
        If the kernel is not available.
    ArithmeticError
        If the state stops being finite (the run diverged).
    """
    library, arrays = _checked(x, states, substeps, phi, drive, decay, springs, quadratic,
                               centre, kick)
    n = len(decay)
    status = library.nonlinear_run(n, arrays[1].shape[0], int(substeps), arrays[0].ctypes.data,
                                   arrays[1].ctypes.data, x.ctypes.data, arrays[2].ctypes.data,
                                   float(v_eps), *(a.ctypes.data for a in arrays[3:]),
                                   states.ctypes.data)
    if status != 0:
        raise ArithmeticError("nonlinear oscillator: the simulation diverged")


def friction_loop(phi: np.ndarray, drive: np.ndarray, x: np.ndarray, substeps: int,
                  half: np.ndarray, full: np.ndarray, v_eps: float, states: np.ndarray) -> None:
    """The reference: :func:`friction_run`'s loop in Python (same arguments, same effect)."""
    n = len(half)
    inverse = 1.0 / v_eps
    for step in range(len(drive)):
        x[:] = phi @ x + drive[step]
        v = np.clip(x[n:] * inverse, -700.0, 700.0)
        if (step + 1) % substeps == 0:  # record F(h/2) applied
            out = states[(step + 1) // substeps]
            out[:n] = x[:n]
            out[n:] = x[n:] + v_eps * (np.arcsinh(np.sinh(v) * half) - v)
        x[n:] += v_eps * (np.arcsinh(np.sinh(v) * full) - v)


def run(phi: np.ndarray, drive: np.ndarray, x: np.ndarray, substeps: int, half: np.ndarray,
        full: np.ndarray, v_eps: float, states: np.ndarray, *, compiled: bool | None = None
        ) -> str:
    """:func:`friction_run` when available (or `compiled` True), else :func:`friction_loop`;
    returns the path taken, ``"compiled"`` or ``"python"``."""
    if compiled is None:
        compiled = available() and len(half) <= MAX_MASSES
    if compiled:
        friction_run(phi, drive, x, substeps, half, full, v_eps, states)
        return "compiled"
    friction_loop(phi, drive, x, substeps, half, full, v_eps, states)
    return "python"


__all__ = ["run", "friction_run", "nonlinear_run", "friction_loop", "load_library", "available", "enabled", "C_SOURCE", "SWITCH_VARIABLE",
           "CACHE_VARIABLE", "MAX_MASSES", "BUILD"]
