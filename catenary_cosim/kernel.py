"""The catenary's Newmark step as a small compiled kernel (C, built on first use, cached).

LAPACK's banded solve (``dpbtrs``) spends most of its time in per-column calls and divisions,
not in arithmetic: for the 4 798 unknowns of the EN 50318 line it alone costs about as much as
the whole step may to run ten times faster than real time. This kernel does the same step as
`panto.catenary_cosim.integration.NewmarkIntegrator`'s NumPy path in plain loops:

* ``catenary_solve``: right-hand side = history + point load; forward and back substitution with
  the factor A = W^T D W (W unit upper triangular, half-bandwidth 4, from the ``dpbtrf``
  Cholesky factor U: W = diag(U)^-1 U, D = diag(U)^2), no division in the loops; then the
  dropper stretches e = e0 + B u; returns the number of slack droppers (the caller corrects the
  solution by its active-set method before the update when there are any);
* ``catenary_step``: the whole step on the integrator's buffers (:class:`CatenaryState`): the
  solve, the slack droppers' correction (the active-set method of
  `panto.catenary_cosim.integration.SlackDropperSolver`, on the same Z = A^-1 B^T and
  G = B Z), the work of the load, then in one pass K_s u (banded), the dissipation increment,
  the history recurrence and u_n <- u_{n+1}; the droppers' trapezoid defect;
* ``catenary_advance`` and ``catenary_height``: `Catenary.advance` (the load shared by the
  element's two nodes) and `Catenary.contact_wire_height` on that state, for the co-simulation
  loop in C (`panto.catenary_cosim.coupling_kernel`).

The source is compiled with the system C compiler (``$CC``, ``cc`` or ``gcc``, as for the FMUs)
into ``$PANTO_KERNEL_CACHE`` or ``~/.cache/panto/kernels/<hash of the source>/`` the first time
it is needed (about 0.3 s), built in a temporary file and moved into place so that parallel
workers never load half a file. Without a compiler, or with ``PANTO_CATENARY_KERNEL=0``, the
integrator keeps its NumPy/LAPACK path, which gives the same iterates to round-off.
"""
from __future__ import annotations

import ctypes
from functools import lru_cache

import numpy as np

from panto.fmu_src import c_kernels

#: Environment variable: ``0`` switches the compiled kernel off (NumPy/LAPACK path).
SWITCH_VARIABLE = "PANTO_CATENARY_KERNEL"
#: Compiler flags of the catenary kernels.
FLAGS = ("-O3", "-fopenmp-simd")
#: Environment variable naming the kernel cache folder (default ``~/.cache/panto/kernels``).
CACHE_VARIABLE = c_kernels.CACHE_VARIABLE
#: Active-set passes of block pivoting before Murty's least-index rule takes over, and the most
#: passes allowed (`panto.catenary_cosim.integration.SlackDropperSolver`, and the C step).
BLOCK_PIVOTING_ITERATIONS = 20
MAX_ACTIVE_SET_ITERATIONS = 2000

C_SOURCE = r"""
/* The catenary's Newmark step (panto.catenary_cosim.kernel). Half-bandwidth 4. */
#include <math.h>
#define BLOCK_PIVOTING_ITERATIONS @BLOCK@
#define MAX_ACTIVE_SET_ITERATIONS @MAX@
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
    /* the last four values stay in registers (no store-to-load on the chain), unrolled by four
       so that they are renamed, not moved (a move lengthens the chain) */
#define FORWARD(J, Y4, Y3, Y2, Y1) do { const double *c = w + 4 * (long)(J); \
        Y4 = u[J] - c[0] * Y4 - c[1] * Y3 - c[2] * Y2 - c[3] * Y1; u[J] = Y4; } while (0)
#define BACK(I, X4, X3, X2, X1) do { \
        X4 = dinv[I] * u[I] - w[4 * (long)((I) + 4)] * X4 - w[4 * (long)((I) + 3) + 1] * X3 \
             - w[4 * (long)((I) + 2) + 2] * X2 - w[4 * (long)((I) + 1) + 3] * X1; \
        u[I] = X4; } while (0)
    if (n > 4) {
        double y4 = u[0], y3 = u[1], y2 = u[2], y1 = u[3];
        for (j = 4; j + 3 < n; j += 4) {
            FORWARD(j, y4, y3, y2, y1);
            FORWARD(j + 1, y3, y2, y1, y4);
            FORWARD(j + 2, y2, y1, y4, y3);
            FORWARD(j + 3, y1, y4, y3, y2);
        }
        for (; j < n; j++) {
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
        for (i = n - 5; i >= 3; i -= 4) {
            BACK(i, x4, x3, x2, x1);
            BACK(i - 1, x3, x2, x1, x4);
            BACK(i - 2, x2, x1, x4, x3);
            BACK(i - 3, x1, x4, x3, x2);
        }
        for (; i >= 0; i--) {
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
   zero). One pass, in place: ks <- K_s v, dissipation[0] = change . (alpha M) change,
   dissipation[1] = change . (K_s v - K_s u) with change = v - u; h <- hu v + kb ks - h - hs s;
   s <- 2 c1 v - s; u <- v. */
static double structure_row(long n, const double *k, const double *u, long i)
{
    double y = k[i] * u[i];
    long m;
    for (m = 1; m <= 4; m++) {
        if (i + m < n) y += k[m * n + i] * u[i + m];
        if (i - m >= 0) y += k[m * n + i - m] * u[i - m];
    }
    return y;
}

#define UPDATE_ROW(I, KS) do { \
        double y_ = (KS), change_ = v[I] - u[I]; \
        m0 += alpha_mass[I] * change_ * change_; \
        s0 += change_ * (y_ - ks[I]); \
        ks[I] = y_; \
        h[I] = hu[I] * v[I] + kb * y_ - h[I] - hs[I] * s[I]; \
        s[I] = 2.0 * c1 * v[I] - s[I]; \
        u[I] = v[I]; } while (0)

static void update_in_place(long n, double *restrict u, const double *restrict v,
                            double *restrict s, double *restrict h, double *restrict ks,
                            const double *restrict k, const double *restrict hu,
                            const double *restrict hs, const double *restrict alpha_mass,
                            double kb, double c1, long odd, double *dissipation)
{
    const double *k1 = k + n, *k2 = k + 2 * n, *k3 = k + 3 * n, *k4 = k + 4 * n;
    double m0 = 0.0, s0 = 0.0;
    long i, middle_end = n - 4 > 4 ? n - 4 : 4;
    FLUSH_SUBNORMALS;
    for (i = 0; i < n && i < 4; i++) UPDATE_ROW(i, structure_row(n, k, v, i));
    /* the simd pragma lets the two sums be vectorised (reassociated) */
    if (odd) {
#pragma omp simd reduction(+:m0, s0)
        for (i = 4; i < n - 4; i++)
            UPDATE_ROW(i, k[i] * v[i] + k1[i] * v[i + 1] + k1[i - 1] * v[i - 1]
                          + k2[i] * v[i + 2] + k2[i - 2] * v[i - 2] + k3[i] * v[i + 3]
                          + k3[i - 3] * v[i - 3] + k4[i] * v[i + 4] + k4[i - 4] * v[i - 4]);
    } else {  /* the wires alone: only the offsets 0, 2 and 4 hold anything */
#pragma omp simd reduction(+:m0, s0)
        for (i = 4; i < n - 4; i++)
            UPDATE_ROW(i, k[i] * v[i] + k2[i] * v[i + 2] + k2[i - 2] * v[i - 2]
                          + k4[i] * v[i + 4] + k4[i - 4] * v[i - 4]);
    }
    for (i = middle_end; i < n; i++) UPDATE_ROW(i, structure_row(n, k, v, i));
    dissipation[0] = m0;
    dissipation[1] = s0;
    RESTORE_MODE;
}

/* ---- the whole step on fixed buffers (catenary_state, mirrored by kernel.CatenaryState) ---- */
typedef struct {
    long n, droppers, elements, odd;
    const double *w, *dinv, *rows, *hu, *hs, *alpha_mass;
    const long *index;
    const double *weight, *e0, *stiffness, *z, *g, *static_height;
    double kb, c1, beta, time_step, element_length;
    double *u, *fresh, *s, *h, *ks, *stretch, *stretch_old;
    double *system, *coefficients, *corrected;
    long *slack, *members;
    double work, dissipated, defect;
    long iterations, load_count, load_index[4];
    double load_value[4];
} catenary_state;

/* x = A^{-1} b for a dense m x m row-major A (partial pivoting; A and b are overwritten, x in b).
   Returns 1 for a singular matrix. */
static int dense_solve(long m, double *a, double *b)
{
    long i, j, r;
    for (j = 0; j < m; j++) {
        long p = j;
        for (i = j + 1; i < m; i++)
            if (fabs(a[i * m + j]) > fabs(a[p * m + j])) p = i;
        if (a[p * m + j] == 0.0) return 1;
        if (p != j) {
            double t;
            for (r = 0; r < m; r++) { t = a[j * m + r]; a[j * m + r] = a[p * m + r]; a[p * m + r] = t; }
            t = b[j]; b[j] = b[p]; b[p] = t;
        }
        for (i = j + 1; i < m; i++) {
            double f = a[i * m + j] / a[j * m + j];
            for (r = j; r < m; r++) a[i * m + r] -= f * a[j * m + r];
            b[i] -= f * b[j];
        }
    }
    for (j = m - 1; j >= 0; j--) {
        double x = b[j];
        for (r = j + 1; r < m; r++) x -= a[j * m + r] * b[r];
        b[j] = x / a[j * m + j];
    }
    return 0;
}

/* The slack droppers' correction of SlackDropperSolver.correct (same block pivoting, then
   Murty's least-index rule): fresh += Z_S c, stretch <- corrected. 0, or -1 (did not settle)
   or -2 (singular system). */
static int correct_slack(catenary_state *c)
{
    long D = c->droppers, n = c->n, d, a, b, m, i, iteration;
    double *e = c->stretch, *A = c->system, *x = c->coefficients, *out = c->corrected;
    const double *G = c->g, *k = c->stiffness;
    for (d = 0; d < D; d++) c->slack[d] = e[d] < 0.0;
    for (iteration = 1; iteration <= MAX_ACTIVE_SET_ITERATIONS; iteration++) {
        long wrong = 0;
        c->iterations = iteration;
        for (m = 0, d = 0; d < D; d++) if (c->slack[d]) c->members[m++] = d;
        for (a = 0; a < m; a++) {
            long p = c->members[a];
            for (b = 0; b < m; b++)
                A[a * m + b] = (a == b ? 1.0 : 0.0) - k[p] * G[p * D + c->members[b]];
            x[a] = k[p] * e[p];
        }
        if (dense_solve(m, A, x)) return -2;
        for (d = 0; d < D; d++) {
            double y = 0.0;
            for (a = 0; a < m; a++) y += G[d * D + c->members[a]] * x[a];
            out[d] = e[d] + y;
            if (c->slack[d] ? out[d] > 0.0 : out[d] < 0.0) {
                if (iteration <= BLOCK_PIVOTING_ITERATIONS || !wrong) c->slack[d] = !c->slack[d];
                wrong++;
            }
        }
        if (!wrong) {
            for (i = 0; i < n; i++) {
                double y = 0.0;
                for (a = 0; a < m; a++) y += c->z[c->members[a] * n + i] * x[a];
                c->fresh[i] += y;
            }
            for (d = 0; d < D; d++) e[d] = out[d];
            return 0;
        }
    }
    return -1;
}

/* Exact minus trapezoidal change of the droppers' energy over the step (integration.py). */
static double trapezoid_defect(const catenary_state *c)
{
    double sum = 0.0;
    long d;
    for (d = 0; d < c->droppers; d++) {
        double before = c->stretch_old[d], after = c->stretch[d], k = c->stiffness[d];
        double p0 = before > 0.0 ? before : 0.0, p1 = after > 0.0 ? after : 0.0;
        double f0 = k * p0, f1 = k * p1;
        sum += 0.5 * (f1 * p1 - f0 * p0) - 0.5 * (f0 + f1) * (after - before);
    }
    return sum;
}

/* One step with point loads at t_{n+1} (NewmarkIntegrator.step): solve, slack correction,
   work, update, dissipation and defect; u, s, h, K_s u and the stretch stay in their buffers.
   Returns 0, or the correction's error code. */
int catenary_step(catenary_state *c, long n_load, const long *load_index,
                  const double *load_value)
{
    long i, d, was_slack = 0;
    double work = 0.0, work_old = 0.0, dissipation[2];
    int slack, status = 0;
    for (d = 0; d < c->droppers; d++) {
        c->stretch_old[d] = c->stretch[d];
        if (c->stretch[d] < 0.0) was_slack = 1;
    }
    slack = catenary_solve((int)c->n, c->w, c->dinv, c->h, (int)n_load, load_index, load_value,
                           c->fresh, (int)c->droppers, c->index, c->weight, c->e0, c->stretch);
    c->iterations = 0;
    if (slack) {
        FLUSH_SUBNORMALS;
        status = correct_slack(c);
        RESTORE_MODE;
        if (status) return status;
    }
    for (i = 0; i < n_load; i++)
        work += load_value[i] * (c->fresh[load_index[i]] - c->u[load_index[i]]);
    for (i = 0; i < c->load_count; i++)
        work_old += c->load_value[i] * (c->fresh[c->load_index[i]] - c->u[c->load_index[i]]);
    c->work += 0.5 * (work + work_old);
    update_in_place(c->n, c->u, c->fresh, c->s, c->h, c->ks, c->rows, c->hu, c->hs,
                    c->alpha_mass, c->kb, c->c1, c->odd, dissipation);
    c->dissipated += (dissipation[0] + c->beta * dissipation[1]) / c->time_step;
    if (c->iterations || was_slack) c->defect += trapezoid_defect(c);
    c->load_count = n_load;
    for (i = 0; i < n_load; i++) {
        c->load_index[i] = load_index[i];
        c->load_value[i] = load_value[i];
    }
    return 0;
}

/* Element j holding x and the local coordinate xi (Catenary._locate, without the range check). */
static long locate(const catenary_state *c, double x, double *xi)
{
    double s = x / c->element_length;
    long j = (long)s;
    if (j > c->elements - 1) j = c->elements - 1;
    *xi = s - (double)j;
    return j;
}

/* One step with the upward point force `force` [N] at x [m] (Catenary.advance). */
int catenary_advance(catenary_state *c, double force, double x)
{
    long index[2], count = 0, k;
    double value[2], xi;
    long j = locate(c, x, &xi);
    for (k = 0; k < 2; k++) {
        long node = j + k;
        if (0 < node && node < c->elements) {
            index[count] = 2 * (node - 1);
            value[count++] = force * (k ? xi : 1.0 - xi);
        }
    }
    return catenary_step(c, count, index, value);
}

/* The absolute contact-wire height at x [m] (Catenary.contact_wire_height). */
double catenary_height(const catenary_state *c, double x)
{
    double xi;
    long j = locate(c, x, &xi);
    double lower = j > 0 ? c->u[2 * (j - 1)] : 0.0;
    double upper = j + 1 < c->elements ? c->u[2 * j] : 0.0;
    return (1.0 - xi) * (c->static_height[j] + lower) + xi * (c->static_height[j + 1] + upper);
}
""".replace("@BLOCK@", str(BLOCK_PIVOTING_ITERATIONS)).replace(
    "@MAX@", str(MAX_ACTIVE_SET_ITERATIONS))

_POINTER = ctypes.c_void_p


class CatenaryState(ctypes.Structure):
    """The C step's ``catenary_state``: sizes, the constant arrays' and the buffers' addresses,
    the coefficients and the energy counters (``work``, ``dissipated``, ``defect`` [J])."""

    _fields_ = ([(name, ctypes.c_long) for name in ("n", "droppers", "elements", "odd")]
                + [(name, _POINTER) for name in (
                    "w", "dinv", "rows", "hu", "hs", "alpha_mass", "index", "weight", "e0",
                    "stiffness", "z", "g", "static_height")]
                + [(name, ctypes.c_double) for name in (
                    "kb", "c1", "beta", "time_step", "element_length")]
                + [(name, _POINTER) for name in (
                    "u", "fresh", "s", "h", "ks", "stretch", "stretch_old", "system",
                    "coefficients", "corrected", "slack", "members")]
                + [(name, ctypes.c_double) for name in ("work", "dissipated", "defect")]
                + [("iterations", ctypes.c_long), ("load_count", ctypes.c_long),
                   ("load_index", ctypes.c_long * 4), ("load_value", ctypes.c_double * 4)])


def enabled() -> bool:
    """False when ``$PANTO_CATENARY_KERNEL`` is ``0`` (or ``false``/``no``/``off``)."""
    return c_kernels.switched_on(SWITCH_VARIABLE)


def build_library(source: str, name: str) -> ctypes.CDLL | None:
    """The shared library ``name.so`` compiled from the C `source` (cached by the source's
    hash, built on first use: :mod:`panto.fmu_src.c_kernels`), or None if it cannot be built."""
    return c_kernels.build_library(source, name, FLAGS)


@lru_cache(maxsize=1)
def load_library() -> ctypes.CDLL | None:
    """The compiled kernel (built into the cache on first use), or None if it cannot be built."""
    library = build_library(C_SOURCE, "catenary_step")
    if library is not None:
        declare_step_functions(library)
    return library


def declare_step_functions(library: ctypes.CDLL) -> None:
    """Argument and result types of the whole-step functions (``catenary_step``,
    ``catenary_advance``, ``catenary_height``) of a library built from :data:`C_SOURCE`."""
    state = ctypes.POINTER(CatenaryState)
    library.catenary_step.restype = ctypes.c_int
    library.catenary_step.argtypes = [state, ctypes.c_long, _POINTER, _POINTER]
    library.catenary_advance.restype = ctypes.c_int
    library.catenary_advance.argtypes = [state, ctypes.c_double, ctypes.c_double]
    library.catenary_height.restype = ctypes.c_double
    library.catenary_height.argtypes = [state, ctypes.c_double]


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


__all__ = ["load_library", "build_library", "declare_step_functions", "CatenaryState",
           "enabled", "unit_factor", "band_rows", "dropper_rows", "C_SOURCE", "SWITCH_VARIABLE",
           "CACHE_VARIABLE", "BLOCK_PIVOTING_ITERATIONS", "MAX_ACTIVE_SET_ITERATIONS"]
