"""MINPACK's Levenberg-Marquardt (:func:`scipy.optimize.least_squares` ``method="lm"``), made
reproducible.

SciPy 1.15 and later run a C translation of MINPACK. Its ``qrfac`` recomputes a column's norm
after heavy cancellation (``rdiag[k] = enorm(m - j, &a[(j + 1) + lda * k])``) over one element
too many: the first element of the next column, and for the last column the eight bytes after
the Jacobian's buffer (valgrind: "Invalid read of size 8 ... 0 bytes after a block of size
2,160,000", SciPy 1.17.1, a 6000 x 45 Jacobian). The Fortran original reads ``m - j`` elements
from row ``j + 1`` with ``j`` counted from one. The stray value changes only the column pivoting,
so every step is still a valid one, but it makes the result depend on whatever lies on the heap:
the same black box fitted twice in one process gave fits differing in the sixth digit, and
every verdict built on it then varied from run to run.

:func:`levenberg_marquardt` appends one parameter the residuals do not depend on. Its Jacobian
column is exactly zero, so it stays the last column through the pivoting (a column is swapped
only for a strictly larger norm), its own norm is never recomputed, and the stray read of the last
real column meets its zero: the computation then reads only the Jacobian's own memory. The
zero column leaves the steps of the real parameters mathematically those of the problem
without it (its step is zero); MINPACK treats the Jacobian as rank-deficient, which only changes
the lower bound it starts its damping search from.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np
from scipy import optimize


def levenberg_marquardt(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray,
                        jac: Callable[[np.ndarray], np.ndarray] | str = "2-point",
                        **options: Any) -> optimize.OptimizeResult:
    """:func:`scipy.optimize.least_squares` with ``method="lm"`` and `options`, reproducible
    (module notes). The result's ``x``, ``jac`` and ``grad`` are those of the real parameters;
    an array ``x_scale`` is extended by one."""
    x0 = np.asarray(x0, float)
    n = x0.size

    def padded_fun(z: np.ndarray) -> np.ndarray:
        return fun(z[:n])

    padded_jac: Callable[[np.ndarray], np.ndarray] | str = jac
    if callable(jac):
        def padded_jac(z: np.ndarray) -> np.ndarray:
            columns = np.atleast_2d(np.asarray(jac(z[:n]), float))
            return np.hstack([columns, np.zeros((columns.shape[0], 1))])

    scale = options.get("x_scale")
    if scale is not None and not isinstance(scale, str):
        options["x_scale"] = np.append(np.broadcast_to(np.asarray(scale, float), (n,)), 1.0)
    solution = optimize.least_squares(padded_fun, np.append(x0, 0.0), jac=padded_jac,
                                      method="lm", **options)
    solution.x = solution.x[:n]
    solution.jac = solution.jac[:, :n]
    solution.grad = solution.grad[:n]
    return solution
