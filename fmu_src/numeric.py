"""The symbolic models as fast Python functions: right-hand side, equilibrium, linearisation.

This is the Python path for fitting scripts. It is compiled (``sympy.lambdify``) from the same
:class:`~panto.fmu_src.symbolic.MechanicalModel` as the C code of the FMUs, so the two paths share the
equations but not the code that evaluates them.

Compiling takes seconds for the pantograph, so the generated source and its compiled code are
cached on disk (``$PANTO_NUMERIC_CACHE``, default ``~/.cache/panto/numeric``) under a hash of the
model's expressions and of this code (:func:`cache_key`); later processes load it in
milliseconds (:func:`cached_functions`, also used with :func:`source_cache_key`, a key read from
the model sources without deriving the model, for the pantograph at rest).
"""
from __future__ import annotations

import builtins
import hashlib
import inspect
import importlib.util
import linecache
import marshal
import math
import sys
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# SymPy and SciPy are imported where they are called: reading cached functions needs neither.
from panto.fmu_src.disk_cache import (default_cache_dir, prune, read_verified, source_digest,
                                      sympy_version, write_atomic)

if TYPE_CHECKING:
    from panto.fmu_src.symbolic import MechanicalModel


class ModelEvaluationError(ValueError):
    """The model cannot be evaluated at this point (e.g. the linkage cannot close)."""


@dataclass(frozen=True)
class LinearisedModel:
    """``dx/dt = A dx + B du``, ``y = y0 + C dx + D du`` about an equilibrium (thesis eq. 2.29-2.30).

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        State-space matrices (x = [q; v], u = inputs, y = outputs).
    x0, u0, y0 : numpy.ndarray
        Operating point: equilibrium state, inputs and outputs.
    state_names, input_names, output_names : tuple of str
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]

    @property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of A [1/s]."""
        return np.linalg.eigvals(self.A)

    @property
    def natural_frequencies_hz(self) -> np.ndarray:
        """Undamped natural frequencies |lambda| / 2 pi of the oscillatory modes, ascending [Hz]."""
        ev = self.eigenvalues
        return np.sort(np.abs(ev[ev.imag > 0]) / (2 * np.pi))

    def to_control(self):
        """The model as a ``control.StateSpace`` (deviations from the operating point)."""
        import control

        return control.ss(self.A, self.B, self.C, self.D, states=list(self.state_names),
                          inputs=list(self.input_names), outputs=list(self.output_names))


def _as_lists(expression):
    """Matrices as nested lists (lambdify's math printer has no matrix type)."""
    import sympy as sp  # only where functions are derived

    if isinstance(expression, sp.MatrixBase):
        return expression.tolist()
    if isinstance(expression, (list, tuple)):
        return [_as_lists(e) for e in expression]
    return expression


def _cse_nested(expression):
    """``sympy.cse`` over every leaf of nested lists, keeping the nesting (lambdify's callable
    ``cse``). ``cse=True`` leaves nested lists (our matrices) without any elimination: the
    pantograph's forces then repeat ``sin(phi2 + phi3)`` 1688 times."""
    import sympy as sp  # only where functions are derived

    leaves = []

    def collect(item):
        if isinstance(item, list):
            return [collect(element) for element in item]
        leaves.append(sp.sympify(item))
        return len(leaves) - 1

    shape = collect(expression)
    replacements, reduced = sp.cse(leaves)

    def rebuild(item):
        return [rebuild(element) for element in item] if isinstance(item, list) else reduced[item]

    return replacements, rebuild(shape)


# --- cache of the compiled functions ----------------------------------------------------------

#: Bumped when the layout of a cache file changes (2: the generated source kept beside its code).
_CACHE_FORMAT = 2


def _digest_expression(expression, memo: dict) -> bytes:
    """Structural SHA-256 of a SymPy expression, stable across processes.

    Shared sub-expressions are hashed once (``memo`` is keyed by object id; the caller keeps the
    expressions alive), so the 35 000-node pantograph takes milliseconds where ``srepr`` takes
    half a second.
    """
    import sympy as sp  # the expressions are SymPy's: already imported

    if expression is None:
        return b"None"
    key = id(expression)
    if key not in memo:
        if isinstance(expression, sp.MatrixBase):
            expression = sp.ImmutableMatrix(expression)
        elif not isinstance(expression, sp.Basic):
            expression = sp.sympify(expression)
        if expression.args:
            parts = b"".join(_digest_expression(a, memo) for a in expression.args)
        else:
            parts = sp.srepr(expression).encode()  # atoms: symbol name and assumptions, numbers
        memo[key] = (hashlib.sha256(type(expression).__name__.encode() + b"(" + parts + b")")
                     .digest(), expression)
    return memo[key][0]


@lru_cache(maxsize=1)
def _code_digest() -> bytes:
    """Hash of the code that turns a model into functions (this module and the derivatives)."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256(f"{_CACHE_FORMAT} {sympy_version()} {sys.version}".encode())
    digest.update(importlib.util.MAGIC_NUMBER)  # the bytecode format of the cached code
    for name in ("numeric.py", "symbolic.py"):
        digest.update((here / name).read_bytes())
    return digest.digest()


def cache_key(model: MechanicalModel) -> str:
    """Key of a model's compiled functions: a hash of its expressions and of the compiling code.

    Every expression the functions are derived from enters the key (mass matrix, forces,
    outputs, energy, dependents with their partials, guards, the initial-guess height, the
    symbols and their order), so a changed model never meets a stale cache file.
    """
    memo: dict = {}
    digest = hashlib.sha256(_code_digest() + model.name.encode())
    parts = [model.p, model.q, model.v, model.u, model.mass_matrix, model.forces,
             model.output_expressions, model.energy, [g.expression for g in model.guards]]
    for dependent in model.dependents:
        partials = sorted(dependent.partials.items(), key=lambda item: str(item[0]))
        parts += [dependent.symbol, dependent.expression, [k for k, _ in partials],
                  [v for _, v in partials]]
    bisect = model.extra.get("initial_guess", {}).get("bisect")
    parts.append(bisect[1] if bisect else None)
    for part in parts:
        items = part if isinstance(part, (list, tuple)) else [part]
        digest.update(b"[" + b"".join(_digest_expression(item, memo) for item in items) + b"]")
    return digest.hexdigest()[:24]


@lru_cache(maxsize=1)
def _namespace() -> dict:
    """The globals lambdify gives a ``modules="math"`` function: ``from math import *``, SymPy's
    translations of its names (``sympy.printing.pycode``) and the builtins lambdify adds; written
    out so that cached functions run without importing SymPy."""
    namespace = {name: getattr(math, name) for name in dir(math) if not name.startswith("_")}
    namespace.update(ceiling=math.ceil, E=math.e, ln=math.log, Abs=abs, builtins=builtins,
                     range=range)
    return namespace


def _code_objects(functions, filename: str):
    """The generated source and its compiled code for each function (same nesting as
    ``functions``; a tuple is kept as a constant). Every function is compiled under its own
    ``filename`` (``<file:name[i]>``), so that :func:`inspect.getsource` finds it again."""
    if functions is None:
        return None
    if isinstance(functions, list):
        return [_code_objects(f, f"{filename}[{i}]") for i, f in enumerate(functions)]
    if isinstance(functions, tuple):
        return {"value": functions}
    names = set(functions.__code__.co_names)
    if not names <= set(_namespace()) | set(dir(builtins)):
        raise ValueError(f"generated code uses names outside the math namespace: {sorted(names)}")
    source = inspect.getsource(functions)
    return {"source": source, "code": compile(source, filename, "exec")}


def _functions_from_code(code):
    """Functions from the stored sources (inverse of :func:`_code_objects`); each source is
    registered with :mod:`linecache` under its code's file name, as ``lambdify`` does, so
    :func:`inspect.getsource` reads it (the C translation of the static functions does)."""
    if code is None:
        return None
    if isinstance(code, list):
        return [_functions_from_code(c) for c in code]
    if "value" in code:
        return code["value"]
    source, compiled = code["source"], code["code"]
    linecache.cache[compiled.co_filename] = (len(source), None, source.splitlines(True),
                                             compiled.co_filename)
    namespace = dict(_namespace())
    exec(compiled, namespace)  # noqa: S102 - our own generated code, checked by its digest
    return namespace["_lambdifygenerated"]


def read_cached_functions(path: Path, key: str) -> dict | None:
    """The compiled functions stored in ``path``, or None if missing, stale or corrupted.

    The file is the SHA-256 of its payload followed by the payload (``marshal`` of the key and,
    per function, its generated source and compiled code); a file whose digest or key does not
    match is never unmarshalled or executed.
    """
    payload = read_verified(path)
    if payload is None:
        return None
    try:
        stored = marshal.loads(payload)
        if stored.get("key") != key:
            return None
        return {name: _functions_from_code(code) for name, code in stored["functions"].items()}
    except (ValueError, EOFError, KeyError, TypeError, AttributeError):
        return None


def write_cached_functions(path: Path, key: str, functions: dict) -> bool:
    """Store the generated sources and their compiled code atomically (temporary file + rename).

    Returns False (and leaves no file) if the cache folder is not writable.
    """
    try:
        code = {name: _code_objects(f, f"<{path.name}:{name}>") for name, f in functions.items()}
    except (OSError, ValueError, TypeError):  # source not retrievable or foreign names
        return False
    return write_atomic(path, marshal.dumps({"key": key, "functions": code}))


def cached_functions(folder: Path, stem: str, key: str, build) -> tuple[dict, str]:
    """The functions stored as ``folder/<stem>-<key>.bin``, else ``build()``'s, then stored
    (older files of the stem pruned; an unwritable folder or a corrupted file is passed over).

    Returns the functions and where they came from: ``"cache"`` or ``"compiled"``.
    """
    path = folder / f"{stem}-{key}.bin"
    functions = read_cached_functions(path, key)
    if functions is not None:
        return functions, "cache"
    functions = build()
    if write_cached_functions(path, key, functions):
        prune(folder, f"{stem}-*.bin")
    return functions, "compiled"


def source_cache_key(*files: Path) -> str:
    """Key of functions generated from the model sources by the code in `files`: a hash of
    every ``fmu_src/*.py`` with SymPy's and Python's versions
    (:func:`~panto.fmu_src.symbolic.source_digest`), of the code that compiles and caches
    functions (this module) and of `files`, without deriving the model (which costs seconds)."""
    digest = hashlib.sha256(_code_digest() + source_digest().encode())
    for file in files:
        digest.update(Path(file).name.encode() + b"\0" + Path(file).read_bytes())
    return digest.hexdigest()[:24]


class NumericModel:
    """Numerical evaluation of a :class:`MechanicalModel` for a given parameter vector.

    Parameters
    ----------
    model : MechanicalModel
        The symbolic model.
    cache_dir : str or Path or None or False, optional
        Folder of the compiled-function cache (default :func:`default_cache_dir`); ``False``
        compiles without reading or writing the cache.

    Notes
    -----
    All methods take the parameter vector ``p`` in the order of ``model.parameters`` (see
    :meth:`panto.fmu_src.parameters.ParameterSet.vector`).

    Compiling the pantograph (``sympy.lambdify`` with common-subexpression elimination, after
    the exact Jacobians) takes about half a minute, so the generated source is stored in the
    cache folder under :func:`cache_key` and executed again by later processes.
    """

    def __init__(self, model: MechanicalModel, cache_dir: str | Path | None | bool = None):
        self.model = model
        self.cache_dir = cache_dir
        #: Where the compiled functions came from: ``"compiled"`` or ``"cache"``.
        self.source = None
        self.nq = len(model.q)
        self.nu = len(model.u)
        self.ny = len(model.outputs)

    # --- compiled functions -----------------------------------------------------------------
    def _compile(self, expression) -> callable:
        import sympy as sp  # only where functions are derived

        deps = [d.symbol for d in self.model.dependents]
        args = [self.model.p, self.model.q, self.model.v, self.model.u, deps]
        return sp.lambdify(args, _as_lists(expression), modules="math", cse=_cse_nested)

    @cached_property
    def _functions(self) -> dict:
        if self.cache_dir is False:
            self.source = "compiled"
            return self._compile_all()
        folder = default_cache_dir() if self.cache_dir is None else Path(self.cache_dir)
        functions, self.source = cached_functions(folder, self.model.name, cache_key(self.model),
                                                  self._compile_all)
        return functions

    def _compile_all(self) -> dict:
        m = self.model
        bisect = m.extra.get("initial_guess", {}).get("bisect")
        drdq, drdv, drdu = m.forces_jacobian
        dydq, dydv, dydu = m.outputs_jacobian
        return {
            "dependents": [self._compile(d.expression) for d in m.dependents],
            "guards": [self._compile(g.expression) for g in m.guards],
            "mass": self._compile(m.mass_matrix),
            "mass_derivative": self._compile(m.mass_matrix_derivative),
            "forces": self._compile(m.forces),
            "forces_jacobian": self._compile([drdq, drdv, drdu]),
            "outputs": self._compile(m.output_expressions),
            "outputs_jacobian": self._compile([dydq, dydv, dydu]),
            "energy": None if m.energy is None else self._compile(m.energy),
            "height": None if bisect is None else self._compile(bisect[1]),
        }

    def dependents(self, p, q) -> list[float]:
        """Values of the dependent quantities (e.g. phi2, phi3); raises if a guard fails."""
        f = self._functions
        nd = len(self.model.dependents)
        v0, u0 = [0.0] * self.nq, [0.0] * self.nu
        for guard, fun in zip(self.model.guards, f["guards"]):
            if not fun(p, q, v0, u0, [0.0] * nd) >= 0:
                values = {c.name: float(x) for c, x in zip(self.model.coordinates, q)}
                raise ModelEvaluationError(guard.message.format(**values))
        values: list[float] = []
        for fun in f["dependents"]:
            values.append(fun(p, q, v0, u0, values + [0.0] * (nd - len(values))))
        return values

    def _call(self, name: str, p, q, v=None, u=None):
        v = [0.0] * self.nq if v is None else v
        u = [0.0] * self.nu if u is None else u
        deps = self.dependents(p, q)
        return self._functions[name](p, q, v, u, deps)

    def mass_matrix(self, p, q) -> np.ndarray:
        """M(q)."""
        return np.array(self._call("mass", p, q), dtype=float)

    def forces(self, p, q, v, u) -> np.ndarray:
        """r(q, v, u)."""
        return np.array(self._call("forces", p, q, v, u), dtype=float).ravel()

    def outputs(self, p, x, u) -> np.ndarray:
        """y = h(q, v, u) for the state x = [q; v]."""
        q, v = x[: self.nq], x[self.nq:]
        return np.array(self._call("outputs", p, q, v, u), dtype=float).ravel()

    def energy(self, p, x, u) -> float:
        """Total mechanical energy (kinetic + potential + work potential of constant inputs)."""
        q, v = x[: self.nq], x[self.nq:]
        return float(self._call("energy", p, q, v, u))

    def derivatives(self, p, x, u) -> np.ndarray:
        """dx/dt = [v; M^-1 r]."""
        q, v = x[: self.nq], x[self.nq:]
        deps = self.dependents(p, q)
        f = self._functions
        mass = np.array(f["mass"](p, q, v, u, deps), dtype=float)
        r = np.array(f["forces"](p, q, v, u, deps), dtype=float).ravel()
        return np.concatenate([v, np.linalg.solve(mass, r)])

    def jacobians(self, p, x, u) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact ``(df/dx, df/du, dh/dx, dh/du)`` at any state (not only at equilibria).

        ``d(M^-1 r)/dq_k = M^-1 (dr/dq_k - dM/dq_k a)`` with ``a = M^-1 r``.
        """
        n = self.nq
        q, v = np.asarray(x[:n], float), np.asarray(x[n:], float)
        deps = self.dependents(p, q)
        f = self._functions
        mass = np.array(f["mass"](p, q, v, u, deps), dtype=float)
        r = np.array(f["forces"](p, q, v, u, deps), dtype=float).ravel()
        drdq, drdv, drdu = (np.array(a, dtype=float) for a in f["forces_jacobian"](p, q, v, u, deps))
        dmdq = np.array(f["mass_derivative"](p, q, v, u, deps), dtype=float)
        from scipy import linalg  # here, not at module load: the cached paths need no SciPy

        lu = linalg.lu_factor(mass)
        acc = linalg.lu_solve(lu, r)
        correction = np.stack([dmdq[k] @ acc for k in range(n)], axis=1)
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = linalg.lu_solve(lu, drdq - correction)
        A[n:, n:] = linalg.lu_solve(lu, drdv)
        B = np.zeros((2 * n, self.nu))
        B[n:, :] = linalg.lu_solve(lu, drdu)
        dydq, dydv, dydu = (np.array(a, dtype=float) for a in f["outputs_jacobian"](p, q, v, u, deps))
        return A, B, np.hstack([dydq, dydv]), dydu

    # --- equilibrium and linearisation -----------------------------------------------------
    def initial_guess(self, p, u) -> np.ndarray:
        """Starting point of the equilibrium solve (same rule as the C code's).

        For the pantograph: delta = 0, xi = eta, and phi1 such that the cross bar is at eta.
        """
        import sympy as sp  # the model's expressions are SymPy's: already imported

        guess = self.model.extra.get("initial_guess", {})
        subs = dict(zip(self.model.p, p)) | dict(zip(self.model.u, u))
        q = np.array([float(sp.sympify(guess.get("values", {}).get(s.name, 0)).subs(subs))
                      for s in self.model.q])
        if "bisect" not in guess:
            return q
        name, _, target, low, high = guess["bisect"]
        k = [s.name for s in self.model.q].index(name)
        height_of = self._functions["height"]

        def reach(value: float) -> float:
            trial = q.copy()
            trial[k] = value
            return height_of(p, trial, [0.0] * self.nq, u, self.dependents(p, trial))

        aim = float(sp.sympify(target).subs(subs))
        high = self._largest_admissible(p, q, k, low, high)
        h_low, h_high = reach(low), reach(high)
        if (h_low - aim) * (h_high - aim) > 0:
            raise ModelEvaluationError(f"no configuration reaches the height {aim:g} m "
                                       f"(reachable: {h_low:g} m to {h_high:g} m)")
        from scipy import optimize  # here, not at module load: the cached paths need no SciPy

        q[k] = optimize.brentq(lambda value: reach(value) - aim, low, high, xtol=1e-14)
        return q

    def _largest_admissible(self, p, q, k: int, low: float, high: float) -> float:
        """Largest value of coordinate k in [low, high] where the guards hold (bisection)."""
        def admissible(value: float) -> bool:
            trial = q.copy()
            trial[k] = value
            try:
                self.dependents(p, trial)
                return True
            except ModelEvaluationError:
                return False

        if admissible(high):
            return high
        if not admissible(low):
            values = {c.name: float(x) for c, x in zip(self.model.coordinates, q)}
            raise ModelEvaluationError(self.model.guards[0].message.format(**(values | {self.model.q[k].name: low})))
        ok, bad = low, high
        for _ in range(60):
            mid = 0.5 * (ok + bad)
            ok, bad = (mid, bad) if admissible(mid) else (ok, mid)
        return ok

    def equilibrium(self, p, u, q_guess=None, *, tolerance: float = 1e-10) -> np.ndarray:
        """Static equilibrium ``r(q, 0, u) = 0`` by Levenberg-Marquardt (as fsolve in the thesis).

        Returns the state x0 = [q0; 0]. Raises :class:`ModelEvaluationError` if it does not
        converge.
        """
        zeros = np.zeros(self.nq)
        if q_guess is None:
            q_guess = self.initial_guess(p, u)

        def residual(q):
            try:
                return self.forces(p, q, zeros, u)
            except ModelEvaluationError:
                return np.full(self.nq, 1e12)

        def jacobian(q):
            deps = self.dependents(p, q)
            return np.array(self._functions["forces_jacobian"](p, q, zeros, u, deps)[0], float)

        from scipy import optimize  # here, not at module load: the cached paths need no SciPy

        sol = optimize.root(residual, np.asarray(q_guess, float), jac=jacobian, method="lm",
                            options={"xtol": 1e-14, "ftol": 1e-14})
        scale = max(1.0, float(np.max(np.abs(self.forces(p, q_guess, zeros, u)))))
        if not np.all(np.abs(residual(sol.x)) <= tolerance * scale):
            raise ModelEvaluationError(
                f"{self.model.name}: no static equilibrium found for inputs u = {list(u)} "
                f"(residual {np.max(np.abs(residual(sol.x))):.3g}, {sol.message})"
            )
        return np.concatenate([sol.x, zeros])

    def linearise(self, p, x0, u0) -> LinearisedModel:
        """Exact linearisation (eqs. 2.27-2.30) about the state x0 and inputs u0."""
        A, B, C, D = self.jacobians(p, x0, u0)
        m = self.model
        return LinearisedModel(
            A=A, B=B, C=C, D=D, x0=np.asarray(x0, float), u0=np.asarray(u0, float),
            y0=self.outputs(p, x0, u0),
            state_names=tuple(s.name for s in m.coordinates + m.velocities),
            input_names=tuple(s.name for s in m.inputs),
            output_names=tuple(s.name for s in m.outputs),
        )
