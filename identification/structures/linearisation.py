"""The pantograph at rest, fast: equilibrium, exact linearisation, exact discretisation.

For :class:`panto.identification.structures.physical.PhysicalLinear`, which repeats the thesis' steps for every
candidate parameter set (section 4.1.3): static equilibrium by Newton's method, linearisation
(eqs. 2.27-2.30) about it, zero- or first-order-hold discretisation and the free run.

The functions of the model at rest are compiled here from the symbolic model with the velocities
set to zero *before* differentiating (``dr/dq`` at ``v = 0`` has about 1 500 operations instead of
350 000), once (over a second; their generated source is cached on disk by a hash of the model
sources, so later processes load it in milliseconds); their generated Python is translated into C
(:mod:`~panto.identification.structures.static_kernel`: the same operations, bit for bit the same
results, 3 us instead of 55 us per balance), the Python kept as fallback. Small linear algebra
uses numpy, and the matrix exponential is computed here, because scipy's threaded BLAS makes
10 x 10 calls take milliseconds on a loaded two-core machine.
"""
from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
try:  # numpy's own LAPACK gufuncs (private: np.linalg.solve itself where absent or renamed)
    from numpy.linalg import _umath_linalg
except ImportError:  # pragma: no cover - every numpy since 1.8 has it
    _umath_linalg = None
_SOLVE, _SOLVE1 = (getattr(_umath_linalg, name, None) for name in ("solve", "solve1"))

from panto.fmu_src.parameters import ParameterSet
from panto.fmu_src.spec import ParameterSpec
from panto.identification.estimation.base import IdentificationError
from panto.identification.structures import static_kernel


@lru_cache(maxsize=1)
def static_functions() -> dict[str, Callable]:
    """Compiled functions of the pantograph at rest (``v = 0``), loaded once per process
    (:func:`load_static_functions` from the default cache folder).

    Returns ``phi2(p, q)``, ``phi3(p, q, phi2)`` (the linkage angles), ``reach(p, q) ->
    discriminant`` (>= 0 where the linkage closes), ``height(p, q, deps) -> y_cb``,
    ``balance(p, q, u, deps) -> (r, dr/dq)`` and ``linear(p, q, u, deps) -> (M, dr/dv, dr/du,
    h, dh/dq, dh/dv, dh/du)``, all at ``v = 0``, and ``static_parameters``: the indices into
    ``p`` of the parameters the equilibrium depends on (those in ``r``, ``dr/dq``, the linkage
    and ``y_cb`` at rest; not the dampings); with them, the model's constants a run needs
    (``parameter_specs``: the fields of every :class:`~panto.fmu_src.spec.ParameterSpec`;
    ``phi1_search_range`` [rad]), so that a process reading the cache never imports SymPy.
    """
    return load_static_functions()[0]


#: File-name stem of the static functions in the cache folder of the compiled models.
CACHE_STEM = "PantographStatic"


def load_static_functions(cache_dir: str | Path | None = None) -> tuple[dict[str, Callable], str]:
    """The functions of :func:`static_functions` and where they came from (``"cache"`` or
    ``"compiled"``).

    Deriving them (the pantograph in SymPy, its Jacobians at rest, ``lambdify``) takes over a
    second, so their generated source is stored in `cache_dir` (default
    :func:`panto.fmu_src.symbolic.default_cache_dir`) under a hash of the model sources and of
    this module (:func:`panto.fmu_src.numeric.source_cache_key`) and executed again by later
    processes: the same source, so bit for bit the same results. A missing, stale or corrupted
    file is derived again (and replaced where the folder is writable).
    """
    from panto.fmu_src import numeric
    from panto.fmu_src.disk_cache import default_cache_dir

    folder = default_cache_dir() if cache_dir is None else Path(cache_dir)
    return numeric.cached_functions(folder, CACHE_STEM, numeric.source_cache_key(Path(__file__)),
                                    derive_static_functions)


def derive_static_functions() -> dict[str, Callable]:
    """The functions of :func:`static_functions`, derived and compiled in this process."""
    import sympy as sp

    from panto.fmu_src.pantograph import PHI1_SEARCH_RANGE, derive_pantograph

    model = derive_pantograph()
    rest = {v: 0 for v in model.v}
    deps = [d.symbol for d in model.dependents]
    forces = model.forces.subs(rest)
    outputs = model.output_expressions

    def compile_(expression, *args):
        return sp.lambdify(list(args), expression, modules="math", cse=True)

    def lists(matrix):
        return matrix.tolist()

    kin = model.extra["linkage"]
    phi2 = compile_(kin["phi2_expr"], model.p, model.q)
    phi3 = compile_(kin["phi3_expr"].subs(kin["phi2"], sp.Symbol("phi2_value", real=True)),
                    model.p, model.q, sp.Symbol("phi2_value", real=True))
    drdq = model.total_jacobian(forces)
    drdv = model.forces.jacobian(model.v).subs(rest)
    statics = set().union(*(sp.sympify(e).free_symbols for e in (
        forces, drdq, kin["phi2_expr"], kin["phi3_expr"], model.guards[0].expression,
        model.extra["y_cb"])))
    return {
        "static_parameters": tuple(i for i, s in enumerate(model.p) if s in statics),
        "parameter_specs": tuple(dataclasses.astuple(spec) for spec in model.parameters),
        "phi1_search_range": tuple(float(value) for value in PHI1_SEARCH_RANGE),
        "phi2": phi2, "phi3": phi3,
        "reach": compile_(model.guards[0].expression, model.p, model.q),
        "height": compile_(model.extra["y_cb"], model.p, model.q, deps),
        "balance": compile_([lists(forces), lists(drdq)], model.p, model.q, model.u, deps),
        "linear": compile_([lists(model.mass_matrix), lists(drdv), lists(forces.jacobian(model.u)),
                            lists(outputs.subs(rest)),
                            lists(model.total_jacobian(outputs).subs(rest)),
                            lists(outputs.jacobian(model.v).subs(rest)),
                            lists(outputs.jacobian(model.u).subs(rest))],
                           model.p, model.q, model.u, deps),
    }


@lru_cache(maxsize=1)
def _static_kernel() -> static_kernel.StaticKernel | None:
    return static_kernel.load(static_functions(), (len(parameter_defaults()[0]), 3, 2))


def compiled() -> static_kernel.StaticKernel | None:
    """The balance and linearisation compiled from :func:`static_functions`, bit for bit the
    same (:mod:`~panto.identification.structures.static_kernel`), or None (no compiler, or
    ``PANTO_STATIC_KERNEL=0``): the Python functions run."""
    return _static_kernel() if static_kernel.switched_on() else None


def linkage_angles(p: Sequence[float], q: Sequence[float]) -> list[float]:
    """``[phi2, phi3]`` (Freudenstein solution); raises if the linkage cannot close."""
    f = static_functions()
    if not f["reach"](p, q) >= 0.0:
        raise IdentificationError(f"the linkage cannot close at phi1 = {q[0]:.4g} rad, "
                                  f"delta = {q[1]:.4g} m")
    phi2 = f["phi2"](p, q)
    return [phi2, f["phi3"](p, q, phi2)]


def _balance_at(p, u, kernel: static_kernel.StaticKernel | None = None
                ) -> Callable[[Sequence[float]], tuple[np.ndarray, np.ndarray]]:
    """``q -> (r, dr/dq)`` at rest for the parameters `p` and inputs `u`: by `kernel`
    (:func:`compiled`; its ``balance_at``, `p` and `u` written once) where given and where it
    answers, else by the Python functions (which raise where the linkage cannot close)."""
    at = None if kernel is None else kernel.balance_at(p, u)
    function = static_functions()["balance"]

    def balance(q) -> tuple[np.ndarray, np.ndarray]:
        found = None if at is None else at(q)
        if found is not None:
            return found
        r, drdq = function(p, q, u, linkage_angles(p, q))
        return np.array(r, float).ravel(), np.array(drdq, float)
    return balance


def solve_equilibrium(p: np.ndarray, u: Sequence[float], start: np.ndarray | None = None,
                      *, tolerance: float = 1e-9) -> np.ndarray:
    """Coordinates ``q0`` with ``r(q0, 0, u) = 0`` (Newton from `start`, else from the rule of
    :mod:`panto.fmu_src.pantograph`: cross bar at the wire, rod unstretched, head on the wire).

    Raises :class:`IdentificationError` when no equilibrium is found.
    """
    return _settle(p, u, start, tolerance)[0]


def _settle(p: np.ndarray, u: Sequence[float], start: np.ndarray | None = None,
            tolerance: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solve_equilibrium`'s ``q0`` and ``dr/dq`` there (Newton's last balance)."""
    for guess in ([start] if start is not None else []) + [None]:
        q = initial_guess(p, u) if guess is None else np.array(guess, float)
        try:
            return _newton(p, u, q, tolerance)
        except (IdentificationError, ArithmeticError, np.linalg.LinAlgError, ValueError):
            continue
    raise IdentificationError(f"no static equilibrium for eta = {u[0]:.4g} m, p = {u[1]:.4g} bar "
                              "with these parameters")


def _newton(p, u, q, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    balance = _balance_at(p, u, compiled())
    r, jac = balance(q)
    scale = max(1.0, float(np.max(np.abs(r))), abs(p[INDEX["k_p"]] * u[1]))
    norm = _norm(r)
    for _ in range(50):
        step = _linear_solve(jac, -r)
        lam = 1.0
        while True:  # backtracking keeps the linkage closed and the residual falling
            try:
                trial = q + lam * step
                r_new, jac_new = balance(trial)
                norm_new = _norm(r_new)
                if norm_new < norm or lam < 1e-3:
                    break
            except IdentificationError:
                pass
            lam *= 0.5
            if lam < 1e-4:
                raise IdentificationError("Newton step left the admissible configurations")
        q, r, jac, norm = trial, r_new, jac_new, norm_new
        # max |r| <= bound and max |lam step| < 1e-9, element by element (a NaN fails both ways)
        bound = tolerance * scale
        if all(abs(x) <= bound for x in r.tolist()) and \
                all(abs(lam * s) < 1e-9 for s in step.tolist()):
            return q, jac
    raise IdentificationError("Newton's method did not converge to an equilibrium")


def _linear_solve(matrix: np.ndarray, right: np.ndarray) -> np.ndarray:
    """``np.linalg.solve(matrix, right)`` of a float square `matrix` and a float vector or
    matrix `right`: its LAPACK gufunc under its error state (a singular `matrix` raises
    :class:`numpy.linalg.LinAlgError`), without its dispatch and checks (Newton solves some
    180 000 3 x 3 systems in one mapping of the data, ``initial_from_data``)."""
    if _SOLVE is None or _SOLVE1 is None:  # pragma: no cover
        return np.linalg.solve(matrix, right)
    solve = _SOLVE1 if right.ndim == 1 else _SOLVE
    with np.errstate(call=_singular, invalid="call", over="ignore", divide="ignore",
                     under="ignore"):
        return solve(matrix, right, signature="dd->d")


def _singular(error: str, flag: int) -> None:
    """The error callback of :func:`_linear_solve`: numpy's own for ``np.linalg.solve``."""
    raise np.linalg.LinAlgError("Singular matrix")


def _norm(r: np.ndarray) -> float:
    """``np.linalg.norm(r)`` of a float vector, the same operations (``sqrt(r . r)``) without
    its dispatch (Newton takes the norm some 650 000 times in one diagnosis)."""
    return math.sqrt(r.dot(r))


def initial_guess(p: np.ndarray, u: Sequence[float]) -> np.ndarray:
    """Cross bar at the wire height (bisection on phi1), ``delta = 0``, head on the wire."""
    from scipy import optimize  # here, not at module load: a cached balance needs no SciPy

    f, kernel = static_functions(), compiled()
    low, high = f["phi1_search_range"]
    grid = np.linspace(low, high, 136)
    reach = None if kernel is None else kernel.reach_grid(p, [0.0, 0.0, u[0]], grid)
    ok = ([phi for phi in grid if f["reach"](p, [phi, 0.0, u[0]]) >= 0.0] if reach is None
          else list(grid[reach >= 0.0]))
    if not ok:
        raise IdentificationError("the linkage closes for no phi1 in the search range")

    def height(phi):
        found = None if kernel is None else kernel.height(p, [phi, 0.0, u[0]])
        return (f["height"](p, [phi, 0.0, u[0]], linkage_angles(p, [phi, 0.0, u[0]]))
                if found is None else found) - u[0]

    heights = [height(phi) for phi in (ok[0], ok[-1])]
    if heights[0] * heights[1] > 0:
        raise IdentificationError(f"no configuration puts the cross bar at {u[0]:.4g} m")
    phi1 = optimize.brentq(height, ok[0], ok[-1], xtol=1e-13)
    return np.array([phi1, 0.0, u[0]])


def linearise(p: np.ndarray, u0: Sequence[float], start: np.ndarray | None = None):
    """``(A, B, C, D, x0, y0)`` of the model about its static equilibrium for the inputs `u0`.

    ``A = [[0, I], [M^-1 dr/dq, M^-1 dr/dv]]``, ``B = [[0], [M^-1 dr/du]]`` (the
    ``dM/dq a`` term of the general Jacobian vanishes because ``a = 0`` at rest);
    ``C = [dh/dq, dh/dv]``, ``D = dh/du``; outputs in the order ``(y_cb, xi, F_c)``.
    """
    q0, drdq = _equilibrium(p, u0, start)
    kernel = compiled()
    found = None if kernel is None else kernel.linear(p, q0, u0)
    mass, drdv, drdu, h, dhdq, dhdv, dhdu = found if found is not None else (
        np.array(a, float) for a in static_functions()["linear"](p, q0, u0, linkage_angles(p, q0)))
    n = len(q0)
    solved = _linear_solve(mass, np.concatenate([drdq, drdv, drdu], axis=1))  # no BLAS threads
    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.eye(n)
    a[n:] = solved[:, :2 * n]
    b = np.zeros((2 * n, drdu.shape[1]))
    b[n:] = solved[:, 2 * n:]
    return (a, b, np.concatenate([dhdq, dhdv], axis=1), dhdu, np.concatenate([q0, np.zeros(n)]),
            h.ravel())


#: Recent equilibria of :func:`linearise` by what they depend on (:func:`_equilibrium`).
_EQUILIBRIA: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_EQUILIBRIA_KEPT = 64


def _equilibrium(p: np.ndarray, u0: Sequence[float], start: np.ndarray | None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``q0 = solve_equilibrium(p, u0, start)`` and ``dr/dq`` there, remembered for the last
    :data:`_EQUILIBRIA_KEPT` keys of the parameters the equilibrium depends on
    (``static_parameters``): a finite-difference column in a damping reuses its base point's
    equilibrium, bit for bit the one computed afresh (every operation of the solve is the same)."""
    key = (np.asarray(p, float)[list(static_functions()["static_parameters"])].tobytes(),
           np.asarray(u0, float).tobytes(),
           None if start is None else np.asarray(start, float).tobytes())
    found = _EQUILIBRIA.pop(key, None)
    if found is None:
        found = _settle(p, u0, start)
        for array in found:
            array.setflags(write=False)
        while len(_EQUILIBRIA) >= _EQUILIBRIA_KEPT:
            _EQUILIBRIA.pop(next(iter(_EQUILIBRIA)))
    _EQUILIBRIA[key] = found  # most recent last
    return found


@lru_cache(maxsize=1)
def default_parameter_set() -> ParameterSet:
    """The pantograph's default parameters (units, bounds, provenance), those of
    :func:`panto.fmu_src.models.default_parameters`, rebuilt from :func:`static_functions`
    (no SymPy)."""
    specs = tuple(ParameterSpec(*fields) for fields in static_functions()["parameter_specs"])
    return ParameterSet("Pantograph", specs)


@lru_cache(maxsize=1)
def parameter_defaults() -> tuple[tuple[str, ...], np.ndarray]:
    """Names and values of the pantograph's default parameters (:func:`default_parameter_set`)."""
    params = default_parameter_set()
    return params.names, params.vector()


INDEX = {name: i for i, name in enumerate(parameter_defaults()[0])}


def discretise(a: np.ndarray, b: np.ndarray, period: float,
               hold: str = "foh") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation ``x[k+1] = Phi x[k] + Gamma_0 u[k] + Gamma_1 (u[k+1] - u[k])``.

    ``expm(T [[A, B, 0], [0, 0, I/T], [0, 0, 0]]) = [[Phi, Gamma_0, Gamma_1], ...]`` (Franklin,
    Powell & Workman, *Digital Control of Dynamic Systems*, sec. 6.3); ``Gamma_1 = 0`` for
    ``"zoh"``, whose inputs are held over the sample.
    """
    n, m = b.shape
    block = np.zeros((n + 2 * m, n + 2 * m))
    block[:n, :n] = a * period
    block[:n, n:n + m] = b * period
    block[n:n + m, n + m:] = np.eye(m)
    e = expm(block)
    return e[:n, :n], e[:n, n:n + m], (e[:n, n + m:] if hold == "foh" else np.zeros((n, m)))


def expm(matrix: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of a degree-18 Taylor polynomial.

    After scaling to ``||A / 2^s||_1 <= 1/2`` the truncation error is below
    ``0.5^19 / 19! ~ 1e-23``. Written with numpy's small products because
    :func:`scipy.linalg.expm` calls a threaded BLAS that is slow for 10 x 10 matrices on a
    loaded machine.
    """
    norm = float(np.max(np.sum(np.abs(matrix), axis=0)))
    squarings = max(0, int(np.ceil(np.log2(norm / 0.5)))) if norm > 0.5 else 0
    scaled = matrix / 2.0 ** squarings
    result = np.eye(len(matrix))
    term = np.eye(len(matrix))
    for order in range(1, 19):
        term = term @ scaled / order
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def propagate(phi: np.ndarray, drive: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """States of ``x[k+1] = Phi x[k] + drive[k]`` from ``x0``, shape ``(len(drive) + 1, n)``.

    In modal coordinates ``z = V^-1 x`` every mode is the first-order filter
    ``z[k+1] = lambda z[k] + g[k]`` (compiled:
    :func:`~panto.identification.structures.static_kernel.first_order_filter`; else
    :func:`scipy.signal.lfilter`: the same values); a complex pair is run once
    and counted twice (``x = sum 2 Re(v z)``). Only real matrix products are used (a complex
    product of this size is slow under a threaded BLAS on a loaded machine). Falls back to the
    plain recursion when the eigenvectors are ill conditioned.
    """
    eigenvalues, vectors = np.linalg.eig(phi)
    if np.linalg.cond(vectors) > 1e8:
        states = np.empty((len(drive) + 1, len(x0)))
        states[0] = x0
        for k in range(len(drive)):
            states[k + 1] = phi @ states[k] + drive[k]
        return states
    inverse = np.linalg.inv(vectors)
    modal_drive = drive @ inverse.real.T + 1j * (drive @ inverse.imag.T)
    z0 = inverse @ x0
    states = np.zeros((len(drive) + 1, len(x0)))
    for i, lam in enumerate(eigenvalues):
        if lam.imag < 0.0:
            continue  # the conjugate of a pair counted twice below
        z = mode_filter(lam, modal_drive[:, i], z0[i])
        weight = 2.0 if lam.imag > 0.0 else 1.0
        if not static_kernel.accumulate_mode(states, z, vectors[:, i], weight):
            states += weight * (np.outer(z.real, vectors[:, i].real)
                                - np.outer(z.imag, vectors[:, i].imag))
    return states


def mode_filter(lam: complex, drive: np.ndarray, z0: complex) -> np.ndarray:
    """One mode's ``z[k+1] = lam z[k] + drive[k]`` from ``z[0] = z0`` (complex, length
    ``len(drive) + 1``): compiled
    (:func:`~panto.identification.structures.static_kernel.first_order_filter`), else by
    :func:`scipy.signal.lfilter` (no compiler, or ``PANTO_STATIC_KERNEL=0``): the same values.
    Shared with :func:`panto.identification.structures.oscillators.propagate`."""
    z = static_kernel.first_order_filter(lam, drive, z0)
    if z is not None:
        return z
    from scipy import signal  # here only: importing scipy.signal takes 0.3 s

    z = np.empty(len(drive) + 1, complex)
    z[0] = z0
    z[1:], _ = signal.lfilter([1.0], [1.0, -lam], drive, zi=[lam * z0])
    return z
