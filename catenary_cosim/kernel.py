"""The catenary's Newmark step as a small compiled kernel (C, built on first use, cached).

LAPACK's banded solve (``dpbtrs``) spends most of its time in per-column calls and divisions,
not in arithmetic: for the 4 798 unknowns of the EN 50318 line it alone costs about as much as
the whole step may to run ten times faster than real time. This kernel does the same step as
`panto.catenary_cosim.integration.NewmarkIntegrator`'s NumPy path in two plain loops:

* ``catenary_solve``: right-hand side = history + point load; forward and back substitution with
  the factor A = W^T D W (W unit upper triangular, half-bandwidth 4, from the ``dpbtrf``
  Cholesky factor U: W = diag(U)^-1 U, D = diag(U)^2), no division in the loops; then the
  dropper stretches e = e0 + B u; returns the number of slack droppers (the caller corrects the
  solution by its active-set method before the update when there are any);
* ``catenary_update``: K_s u (banded), the dissipation increment and the history recurrence of
  the integrator, in one pass.

The source is compiled with the system C compiler (``$CC``, ``cc`` or ``gcc``, as for the FMUs)
into ``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<hash of the source>/`` the first time
it is needed (about 0.3 s), built in a temporary file and moved into place so that parallel
workers never load half a file. Without a compiler, or with ``PANTO_CATENARY_KERNEL=0``, the
integrator keeps its NumPy/LAPACK path, which gives the same iterates to round-off.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np

#: Environment variable: ``0`` switches the compiled kernel off (NumPy/LAPACK path).
SWITCH_VARIABLE = "PANTO_CATENARY_KERNEL"
#: Environment variable naming the kernel cache folder (default ``~/.cache/panto/kernels``).
CACHE_VARIABLE = "PANTO_KERNEL_CACHE"

C_SOURCE = r"""
/* The catenary's Newmark step (panto.catenary_cosim.kernel). Half-bandwidth 4. */
#if defined(__SSE2__)
#include <xmmintrin.h>
/* Subnormal numbers (below 2.2e-308, in the exponentially decaying far field of the implicit
   solve ahead of the load) cost ~100 cycles per operation on x86: flush them to zero inside
   the kernel (MXCSR FTZ | DAZ), restoring the caller's mode on return. */
#define FLUSH_SUBNORMALS unsigned int saved_mxcsr = _mm_getcsr(); _mm_setcsr(saved_mxcsr | 0x8040u)
#define RESTORE_MODE _mm_setcsr(saved_mxcsr)
#else
#define FLUSH_SUBNORMALS
#define RESTORE_MODE
#endif

/* u = A^{-1} (history + load); stretch = e0 + B u; returns the number of slack droppers.
   w[4 j + k] = W(j - 4 + k, j) (0 where j - 4 + k < 0), dinv[j] = 1 / D_j.
   Dropper d acts on unknowns index[4 d + m] with weights weight[4 d + m], m = 0..3. */
int catenary_solve(int n, const double *w, const double *dinv, const double *history,
                   int n_load, const long *load_index, const double *load_value, double *u,
                   int n_droppers, const long *index, const double *weight, const double *e0,
                   double *stretch)
{
    int i, j, slack = 0;
    FLUSH_SUBNORMALS;
    for (i = 0; i < n; i++) u[i] = history[i];
    for (i = 0; i < n_load; i++) u[load_index[i]] += load_value[i];
    /* forward: W^T y = b, the newest term last (it is on the critical path) */
    for (j = 0; j < n && j < 4; j++) {
        double y = u[j];
        for (i = 4 - j; i < 4; i++) y -= w[4 * j + i] * u[j - 4 + i];
        u[j] = y;
    }
    if (n > 4) {  /* the last four values stay in registers (no store-to-load on the chain) */
        double y4 = u[0], y3 = u[1], y2 = u[2], y1 = u[3];
        for (j = 4; j < n; j++) {
            const double *c = w + 4 * (long)j;
            double y = u[j] - c[0] * y4 - c[1] * y3 - c[2] * y2 - c[3] * y1;
            u[j] = y;
            y4 = y3; y3 = y2; y2 = y1; y1 = y;
        }
    }
    /* back: W x = D^{-1} y, row by row, x_{i+1} last */
    for (i = n - 1; i >= 0 && i >= n - 4; i--) {
        double x = dinv[i] * u[i];
        int k;
        for (k = 4; k >= 1; k--)
            if (i + k < n) x -= w[4 * (long)(i + k) + 4 - k] * u[i + k];
        u[i] = x;
    }
    if (n > 4) {
        double x4 = u[n - 1], x3 = u[n - 2], x2 = u[n - 3], x1 = u[n - 4];
        for (i = n - 5; i >= 0; i--) {
            double x = dinv[i] * u[i] - w[4 * (long)(i + 4)] * x4
                       - w[4 * (long)(i + 3) + 1] * x3 - w[4 * (long)(i + 2) + 2] * x2
                       - w[4 * (long)(i + 1) + 3] * x1;
            u[i] = x;
            x4 = x3; x3 = x2; x2 = x1; x1 = x;
        }
    }
    for (i = 0; i < n_droppers; i++) {
        const long *at = index + 4 * (long)i;
        const double *by = weight + 4 * (long)i;
        stretch[i] = e0[i] + (by[0] * u[at[0]] + by[1] * u[at[1]] + by[2] * u[at[2]]
                              + by[3] * u[at[3]]);
        if (stretch[i] < 0.0) slack++;
    }
    RESTORE_MODE;
    return slack;
}

/* k[m n + i] = K_s(i, i + m) for m = 0..4 (0 beyond the end; odd = 0: offsets 1 and 3 all
   zero): ks = K_s u;
   dissipation[0] = change . (alpha M) change, dissipation[1] = change . K_s change;
   h <- hu u + kb ks - h - hs s;  s <- 2 c1 u - s. */
static double structure_row(int n, const double *k, const double *u, int i)
{
    double y = k[i] * u[i];
    int m;
    for (m = 1; m <= 4; m++) {
        if (i + m < n) y += k[(long)m * n + i] * u[i + m];
        if (i - m >= 0) y += k[(long)m * n + i - m] * u[i - m];
    }
    return y;
}

void catenary_update(int n, const double *restrict u_old, const double *restrict u,
                     double *restrict s, double *restrict h, const double *restrict ks_old,
                     double *restrict ks, const double *restrict k, const double *restrict hu,
                     const double *restrict hs, const double *restrict alpha_mass, double kb,
                     double c1, int odd, double *restrict dissipation)
{
    const double *k1 = k + n, *k2 = k + 2 * (long)n, *k3 = k + 3 * (long)n,
                 *k4 = k + 4 * (long)n;
    double m0 = 0.0, s0 = 0.0;
    int i;
    FLUSH_SUBNORMALS;
    for (i = 0; i < n && i < 4; i++) ks[i] = structure_row(n, k, u, i);
    if (odd)
        for (i = 4; i < n - 4; i++)
            ks[i] = k[i] * u[i] + k1[i] * u[i + 1] + k1[i - 1] * u[i - 1] + k2[i] * u[i + 2]
                    + k2[i - 2] * u[i - 2] + k3[i] * u[i + 3] + k3[i - 3] * u[i - 3]
                    + k4[i] * u[i + 4] + k4[i - 4] * u[i - 4];
    else  /* the wires alone: only the offsets 0, 2 and 4 hold anything */
        for (i = 4; i < n - 4; i++)
            ks[i] = k[i] * u[i] + k2[i] * u[i + 2] + k2[i - 2] * u[i - 2]
                    + k4[i] * u[i + 4] + k4[i - 4] * u[i - 4];
    for (i = (n - 4 > 4 ? n - 4 : 4); i < n; i++) ks[i] = structure_row(n, k, u, i);
    /* the simd pragma lets the two sums be vectorised (reassociated) */
#pragma omp simd reduction(+:m0, s0)
    for (i = 0; i < n; i++) {
        double change = u[i] - u_old[i];
        m0 += alpha_mass[i] * change * change;
        s0 += change * (ks[i] - ks_old[i]);
    }
    for (i = 0; i < n; i++) {
        h[i] = hu[i] * u[i] + kb * ks[i] - h[i] - hs[i] * s[i];
        s[i] = 2.0 * c1 * u[i] - s[i];
    }
    dissipation[0] = m0;
    dissipation[1] = s0;
    RESTORE_MODE;
}
"""

_POINTER = ctypes.c_void_p


def enabled() -> bool:
    """False when ``$PANTO_CATENARY_KERNEL`` is ``0`` (or ``false``/``no``/``off``)."""
    return os.environ.get(SWITCH_VARIABLE, "1").strip().lower() not in ("0", "false", "no", "off")


def _cache_folder() -> Path:
    base = os.environ.get(CACHE_VARIABLE) or Path.home() / ".cache" / "panto" / "kernels"
    return Path(base) / hashlib.sha256(C_SOURCE.encode()).hexdigest()[:12]


def _compiler() -> str | None:
    for candidate in (os.environ.get("CC"), "cc", "gcc"):
        if candidate and shutil.which(candidate):
            return candidate
    return None


def _build(target: Path) -> None:
    """Compile the source into the shared library ``target`` (atomically)."""
    compiler = _compiler()
    if compiler is None:
        raise OSError("no C compiler ($CC, cc, gcc)")
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as scratch:
        source = Path(scratch) / "catenary_step.c"
        source.write_text(C_SOURCE)
        built = Path(scratch) / target.name
        subprocess.run([compiler, "-O3", "-fopenmp-simd", "-fPIC", "-shared", "-o", str(built), str(source)],
                       check=True, capture_output=True, timeout=120)
        os.replace(built, target)


@lru_cache(maxsize=1)
def load_library() -> ctypes.CDLL | None:
    """The compiled kernel (built into the cache on first use), or None if it cannot be built."""
    target = _cache_folder() / "catenary_step.so"
    try:
        if not target.exists():
            _build(target)
        library = ctypes.CDLL(str(target))
    except (OSError, subprocess.SubprocessError):
        return None
    library.catenary_solve.restype = ctypes.c_int
    library.catenary_solve.argtypes = [ctypes.c_int, _POINTER, _POINTER, _POINTER, ctypes.c_int,
                                       _POINTER, _POINTER, _POINTER, ctypes.c_int, _POINTER,
                                       _POINTER, _POINTER, _POINTER]
    library.catenary_update.restype = None
    library.catenary_update.argtypes = [ctypes.c_int] + [_POINTER] * 10 + [ctypes.c_double] * 2 \
        + [ctypes.c_int, _POINTER]
    return library


def unit_factor(band: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """W per unknown (n x 4, row j: W(j-4..j-1, j)) and 1/D from the upper ``dpbtrf`` band.

    ``band[4 + i - j, j] = U(i, j)`` with A = U^T U; W = diag(U)^-1 U, D = diag(U)^2.
    """
    diagonal = band[4]
    n = band.shape[1]
    w = np.zeros((n, 4))
    for k in range(4):  # W(j - 4 + k, j) = U(j - 4 + k, j) / U(j - 4 + k, j - 4 + k)
        first = 4 - k
        w[first:, k] = band[k, first:] / diagonal[:n - first]
    return np.ascontiguousarray(w), 1.0 / diagonal**2


def dropper_rows(matrix) -> tuple[np.ndarray, np.ndarray]:
    """B as (droppers x 4) unknown indices and weights, padded with weight 0 at index 0."""
    matrix = matrix.tocsr()
    count = matrix.shape[0]
    index, weight = np.zeros((count, 4), dtype=np.int64), np.zeros((count, 4))
    for d in range(count):
        start, stop = matrix.indptr[d], matrix.indptr[d + 1]
        if stop - start > 4:
            raise ValueError(f"dropper {d} acts on {stop - start} unknowns (at most 4)")
        index[d, :stop - start] = matrix.indices[start:stop]
        weight[d, :stop - start] = matrix.data[start:stop]
    return index, weight


def band_rows(band: np.ndarray) -> np.ndarray:
    """Diagonals (5 x n, row m: K(i, i + m), 0 past the end) of a symmetric matrix from its
    upper band storage."""
    n = band.shape[1]
    rows = np.zeros((5, n))
    for m in range(5):  # K(i, i + m) = band[4 - m, i + m]
        rows[m, :n - m] = band[4 - m, m:]
    return rows


__all__ = ["load_library", "enabled", "unit_factor", "band_rows", "dropper_rows", "C_SOURCE",
           "SWITCH_VARIABLE", "CACHE_VARIABLE"]
