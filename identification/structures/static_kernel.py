"""The pantograph at rest, compiled: the lambdified static functions of
:mod:`panto.identification.structures.linearisation` translated operation for operation into C.

Newton's method for the equilibrium calls the balance ``(r, dr/dq)`` at ``v = 0`` with the
linkage angles some half million times in one rig-story diagnosis, 55-65 us each as SymPy's
generated Python (a 9 000-character expression of scalars). This module reads that generated
Python source (:func:`python_to_c`, through :mod:`ast`) and writes the same expressions as C:
every binary operation with the same operands in the same order, ``x**n`` as libm's ``pow`` (as
CPython's float power and NumPy's scalar power call it), ``sin``, ``cos``, ``atan2``, ``sqrt``
from libm, compiled without fused multiply-adds and without builtin substitutions
(``-ffp-contract=off -fno-builtin``: ``pow(x, 2)`` stays a call, ``sin``/``cos`` never fuse into
``sincos``). Identical subexpressions are computed once (the same operations give the same value),
so the results are bit for bit those of the Python functions.

Where the Python functions raise (the linkage cannot close, a math domain error, a division by
zero) the C results are not finite or the reach test fails: the callers then run the Python
functions, which raise as before. The C source is kept on disk (:func:`kernel_source`); the
library is built at first use by
:mod:`panto.fmu_src.c_kernels` into the kernel cache (keyed by the hash of the generated source);
without a compiler, or with ``PANTO_STATIC_KERNEL=0`` (:data:`SWITCH_VARIABLE`), the Python
functions run.

The first-order filter of every mode in
:func:`~panto.identification.structures.linearisation.propagate` is compiled here too
(:func:`first_order_filter`: the operations of :func:`scipy.signal.lfilter`, so its results bit
for bit, without importing ``scipy.signal``, which takes 0.3 s).
"""
from __future__ import annotations

import ast
import ctypes
import hashlib
import inspect
import sys
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from panto.fmu_src import c_kernels, disk_cache

#: Flags of the build: ISO C, no fused multiply-adds, libm calls kept as written.
COMPILER_FLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-builtin")
#: Environment variable: ``0`` switches the compiled balance off (the Python functions run).
SWITCH_VARIABLE = "PANTO_STATIC_KERNEL"
#: How the library is built and switched (:class:`panto.fmu_src.c_kernels.Kernel`; the source is
#: generated per call of :func:`load`).
BUILD = c_kernels.Kernel("static_balance", SWITCH_VARIABLE, COMPILER_FLAGS)
#: libm functions the translation accepts (CPython's ``math`` calls the same ones).
FUNCTIONS = {"sin", "cos", "tan", "atan2", "sqrt", "exp", "log", "atan", "asin", "acos",
             "sinh", "cosh", "tanh"}
_OPERATORS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/"}
_COMPARISONS = {ast.Gt: ">", ast.GtE: ">=", ast.Lt: "<", ast.LtE: "<=", ast.Eq: "==",
                ast.NotEq: "!="}


class Untranslatable(ValueError):
    """The generated Python uses a construct :func:`python_to_c` does not translate."""


class _Emitter:
    """C text of one function body: statements, and repeated subexpressions as temporaries."""

    def __init__(self, prefix: str) -> None:
        self.prefix, self.lines, self.known = prefix, [], {}
        self.counts: dict[str, int] = {}

    def count(self, node: ast.AST) -> None:
        """Count every call and binary operation outside conditionals (hoisting candidates)."""
        if isinstance(node, ast.IfExp):
            return
        if isinstance(node, (ast.BinOp, ast.Call)):
            key = ast.dump(node)
            self.counts[key] = self.counts.get(key, 0) + 1
        for child in ast.iter_child_nodes(node):
            self.count(child)

    def expression(self, node: ast.AST, hoist: bool = True) -> str:
        """C text of the Python expression `node` (fully parenthesised, same operation order)."""
        key = ast.dump(node) if hoist and isinstance(node, (ast.BinOp, ast.Call)) else None
        if key is not None and key in self.known:
            return self.known[key]
        text = self._plain(node, hoist)
        if key is not None and self.counts.get(key, 0) > 1:
            name = f"{self.prefix}t{len(self.known)}"
            self.lines.append(f"    const double {name} = {text};")
            self.known[key] = name
            return name
        return text

    def _plain(self, node: ast.AST, hoist: bool) -> str:
        sub = lambda n: self.expression(n, hoist)  # noqa: E731
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            return f"({sub(node.left)} {_OPERATORS[type(node.op)]} {sub(node.right)})"
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return f"pow({sub(node.left)}, {sub(node.right)})"
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            return f"({'-' if isinstance(node.op, ast.USub) else '+'}{sub(node.operand)})"
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            value = float(node.value)
            if isinstance(node.value, int) and float(node.value) != node.value:
                raise Untranslatable(f"integer {node.value} not exact as a double")
            return f"({value!r})"
        if isinstance(node, ast.Name):
            return f"v_{node.id}"
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id in FUNCTIONS and not node.keywords:
            return f"{node.func.id}({', '.join(sub(a) for a in node.args)})"
        if isinstance(node, ast.IfExp):  # only the branch taken is evaluated, as in Python
            inner = lambda n: self.expression(n, False)  # noqa: E731
            return f"({inner(node.test)} ? {inner(node.body)} : {inner(node.orelse)})"
        if isinstance(node, ast.BoolOp):
            joint = " && " if isinstance(node.op, ast.And) else " || "
            return "(" + joint.join(sub(v) for v in node.values) + ")"
        if isinstance(node, ast.Compare) and len(node.ops) == 1 \
                and type(node.ops[0]) in _COMPARISONS:
            operator = _COMPARISONS[type(node.ops[0])]
            return f"({sub(node.left)} {operator} {sub(node.comparators[0])})"
        raise Untranslatable(f"cannot translate {ast.dump(node)[:80]}")


def _leaves(node: ast.AST) -> list[ast.AST]:
    """The scalar expressions of a (nested) list display, in row-major order."""
    if isinstance(node, (ast.List, ast.Tuple)):
        return [leaf for element in node.elts for leaf in _leaves(element)]
    return [node]


def python_to_c(source: str, name: str) -> tuple[str, int]:
    """C translation of a function generated by :func:`sympy.lambdify` (``modules="math"``).

    Parameters
    ----------
    source : str
        The generated ``def``: list arguments unpacked by ``[a, b] = arg``, scalar arguments,
        assignments ``x0 = ...`` (common subexpressions) and one ``return`` of a scalar or a
        nested list.
    name : str
        Name of the C function ``static void name(const double *args..., double *out)``:
        list arguments as pointers, scalar ones as ``double``; the returned values written to
        ``out`` in row-major order.

    Returns
    -------
    tuple of (str, int)
        The C function and the number of values it writes.

    Raises
    ------
    Untranslatable
        For any construct outside the arithmetic of the generated functions.
    """
    function = ast.parse(source).body[0]
    if not isinstance(function, ast.FunctionDef):
        raise Untranslatable("not a function definition")
    body = function.body
    unpacked = {s.value.id for s in body if isinstance(s, ast.Assign)
                and isinstance(s.targets[0], (ast.List, ast.Tuple))
                and isinstance(s.value, ast.Name)}
    arguments = [f"const double *v_{a.arg}" if a.arg in unpacked else f"double v_{a.arg}"
                 for a in function.args.args]
    emitter = _Emitter(f"{name}_")
    for statement in body:
        if isinstance(statement, (ast.Assign, ast.Return)) and statement.value is not None:
            emitter.count(statement.value)
    returned = 0
    for statement in body:
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
            target = statement.targets[0]
            if isinstance(target, (ast.List, ast.Tuple)) and isinstance(statement.value, ast.Name):
                for i, element in enumerate(target.elts):
                    emitter.lines.append(f"    const double v_{element.id} = "
                                         f"v_{statement.value.id}[{i}];")
                continue
            if isinstance(target, ast.Name):
                emitter.lines.append(f"    const double v_{target.id} = "
                                     f"{emitter.expression(statement.value)};")
                continue
        if isinstance(statement, ast.Return) and statement.value is not None:
            leaves = _leaves(statement.value)
            values = [emitter.expression(leaf) for leaf in leaves]
            emitter.lines.extend(f"    out[{i}] = {v};" for i, v in enumerate(values))
            returned = len(leaves)
            continue
        raise Untranslatable(f"cannot translate statement {ast.dump(statement)[:80]}")
    head = f"static void {name}({', '.join(arguments + ['double *out'])})"
    return head + " {\n" + "\n".join(emitter.lines) + "\n}\n", returned


def kernel_source(functions: dict[str, Callable], sizes: Sequence[int], *,
                  cache_dir: str | Path | None | bool = None) -> str:
    """The C source of ``panto_static_balance``, ``_linear``, ``_height`` and ``_reach_grid``
    from the lambdified `functions` of
    :func:`~panto.identification.structures.linearisation.static_functions`.

    The first three read ``in = [p (sizes[0]), q (sizes[1]), u (sizes[2])]``, return 1 where the
    linkage cannot close (the reach test ``reach >= 0`` fails), 2 where a result is not finite,
    else 0 with the values of ``balance`` (``linear``, ``height``) at the linkage angles in
    ``out``; ``panto_static_reach_grid(in, phi1, n, out)`` writes ``reach`` at ``q`` with its
    first coordinate set to each of the `n` values ``phi1`` (2 where one is not finite).

    The translation takes 0.1-0.2 s, so it is kept in `cache_dir` (default
    :func:`panto.fmu_src.disk_cache.default_cache_dir`; ``False``: neither read nor written) under
    a hash of the functions' sources, `sizes`, this module and Python's version, checked by its
    SHA-256; a missing or corrupted file is translated again.
    """
    sources = {key: inspect.getsource(functions[key]) for key in _TRANSLATED}
    if cache_dir is False:
        return _translate(sources, sizes)
    digest = hashlib.sha256(f"{sys.version} {tuple(int(s) for s in sizes)}".encode()
                            + Path(__file__).read_bytes())
    for key, text in sources.items():
        digest.update(f"\0{key}\0{text}".encode())
    folder = disk_cache.default_cache_dir() if cache_dir is None else Path(cache_dir)
    path = folder / f"{SOURCE_CACHE_STEM}-{digest.hexdigest()[:24]}.c"
    stored = disk_cache.read_verified(path)
    try:
        if stored is not None:
            return stored.decode()
    except UnicodeDecodeError:  # not a translation: made again
        pass
    source = _translate(sources, sizes)
    if disk_cache.write_atomic(path, source.encode()):
        disk_cache.prune(folder, f"{SOURCE_CACHE_STEM}-*.c")
    return source


#: The static functions translated, in the order of the C source.
_TRANSLATED = ("reach", "phi2", "phi3", "balance", "linear", "height")
#: File-name stem of the stored translations (:func:`kernel_source`).
SOURCE_CACHE_STEM = "StaticKernel"


def _translate(sources: dict[str, str], sizes: Sequence[int]) -> str:
    """The C source of :func:`kernel_source` from the functions' generated `sources`."""
    parts = ["#include <math.h>\n"]
    outputs = {}
    for key in _TRANSLATED:
        text, outputs[key] = python_to_c(sources[key], f"static_{key}")
        parts.append(text)
    n_p, n_q = sizes[0], sizes[1]
    for key, arguments in (("balance", "p, q, u"), ("linear", "p, q, u"), ("height", "p, q")):
        parts.append(f"""
int panto_static_{key}(const double *in, double *out) {{
    const double *p = in, *q = in + {n_p}, *u = in + {n_p + n_q};
    double reach, angles[2];
    static_reach(p, q, &reach);
    if (!(reach >= 0.0)) return 1;
    static_phi2(p, q, &angles[0]);
    static_phi3(p, q, angles[0], &angles[1]);
    static_{key}({arguments}, angles, out);
    for (int i = 0; i < {outputs[key]}; ++i) if (!isfinite(out[i])) return 2;
    return 0;
}}
""")
    parts.append(f"""
int panto_static_reach_grid(const double *in, const double *phi1, int n, double *out) {{
    double q[{n_q}];
    for (int j = 0; j < {n_q}; ++j) q[j] = in[{n_p} + j];
    for (int i = 0; i < n; ++i) {{
        q[0] = phi1[i];
        static_reach(in, q, &out[i]);
        if (!isfinite(out[i])) return 2;
    }}
    return 0;
}}
""")
    return "\n".join(parts)


class StaticKernel:
    """The compiled balance and linearisation (``None`` from a call: take the Python path).

    Parameters
    ----------
    library : ctypes.CDLL
        The library built from :func:`kernel_source`.
    sizes : sequence of int
        Lengths of ``p``, ``q`` and ``u``.
    """

    def __init__(self, library: ctypes.CDLL, sizes: Sequence[int]) -> None:
        self.sizes = tuple(int(s) for s in sizes)
        self._functions = {}
        for key in ("balance", "linear", "height", "reach_grid"):
            function = getattr(library, f"panto_static_{key}")
            function.restype = ctypes.c_int
            function.argtypes = [ctypes.c_void_p, ctypes.c_void_p] + (
                [ctypes.c_int, ctypes.c_void_p] if key == "reach_grid" else [])
            self._functions[key] = function

    def _call(self, key: str, p, q, u, size: int) -> np.ndarray | None:
        n_p, n_q, n_u = self.sizes
        if len(p) != n_p or len(q) != n_q or len(u) != n_u:
            return None
        buffer = np.empty(n_p + n_q + n_u + size)
        buffer[:n_p], buffer[n_p:n_p + n_q], buffer[n_p + n_q:n_p + n_q + n_u] = p, q, u
        address = buffer.ctypes.data
        status = self._functions[key](address, address + 8 * (n_p + n_q + n_u))
        return buffer[n_p + n_q + n_u:] if status == 0 else None

    def balance(self, p, q, u) -> tuple[np.ndarray, np.ndarray] | None:
        """``(r, dr/dq)`` at rest, or None where the Python path must run (module notes)."""
        at = self.balance_at(p, u)
        return None if at is None else at(q)

    def balance_at(self, p, u
                   ) -> Callable[[Sequence[float]], tuple[np.ndarray, np.ndarray] | None] | None:
        """``q -> balance(p, q, u)``, `p` and `u` written once into the buffer it reuses (a
        Newton solve balances some twenty times at the same `p` and `u`), or None where their
        lengths are not the kernel's."""
        n_p, n_q, n_u = self.sizes
        if len(p) != n_p or len(u) != n_u:
            return None
        buffer = np.empty(n_p + n_q + n_u + n_q + n_q * n_q)
        buffer[:n_p], buffer[n_p + n_q:n_p + n_q + n_u] = p, u
        coordinates = buffer[n_p:n_p + n_q]
        r, drdq = buffer[-n_q - n_q * n_q:-n_q * n_q], buffer[-n_q * n_q:].reshape(n_q, n_q)
        address = buffer.ctypes.data
        arguments = (address, address + 8 * (n_p + n_q + n_u))
        function = self._functions["balance"]

        def balance(q) -> tuple[np.ndarray, np.ndarray] | None:
            if len(q) != n_q:
                return None
            coordinates[:] = q
            return (r.copy(), drdq.copy()) if function(*arguments) == 0 else None
        return balance

    def linear(self, p, q, u) -> list[np.ndarray] | None:
        """``(M, dr/dv, dr/du, h, dh/dq, dh/dv, dh/du)`` at rest, or None (module notes)."""
        n, m = self.sizes[1], self.sizes[2]
        shapes = [(n, n), (n, n), (n, m), (n, 1), (n, n), (n, n), (n, m)]
        out = self._call("linear", p, q, u, sum(a * b for a, b in shapes))
        if out is None:
            return None
        arrays, start = [], 0
        for rows, columns in shapes:
            arrays.append(out[start:start + rows * columns].reshape(rows, columns).copy())
            start += rows * columns
        return arrays

    def height(self, p, q) -> float | None:
        """``y_cb`` at rest at the coordinates `q`, or None (module notes)."""
        out = self._call("height", p, q, (0.0,) * self.sizes[2], 1)
        return None if out is None else float(out[0])

    def reach_grid(self, p, q, phi1: np.ndarray) -> np.ndarray | None:
        """The linkage's reach (>= 0 where it closes) at `q` with its first coordinate set to
        each of `phi1`, or None where one is not finite (module notes)."""
        n_p, n_q = self.sizes[:2]
        if len(p) != n_p or len(q) != n_q:
            return None
        buffer = np.empty(n_p + n_q + 2 * len(phi1))
        buffer[:n_p], buffer[n_p:n_p + n_q] = p, q
        buffer[n_p + n_q:n_p + n_q + len(phi1)] = phi1
        address, start = buffer.ctypes.data, 8 * (n_p + n_q)
        status = self._functions["reach_grid"](address, address + start, len(phi1),
                                               address + start + 8 * len(phi1))
        return buffer[n_p + n_q + len(phi1):] if status == 0 else None


def load(functions: dict[str, Callable], sizes: Sequence[int]) -> StaticKernel | None:
    """The compiled kernel of the lambdified `functions` of
    :func:`~panto.identification.structures.linearisation.static_functions` (``p``, ``q``, ``u``
    of lengths `sizes`; built on first use into the kernel cache), or None without a compiler or
    when the translation fails."""
    try:
        source = kernel_source(functions, sizes)
    except (Untranslatable, OSError, TypeError, SyntaxError):
        return None
    return BUILD.load(source, lambda library: StaticKernel(library, sizes))


def switched_on() -> bool:
    """False when ``PANTO_STATIC_KERNEL=0`` (:data:`SWITCH_VARIABLE`): the Python functions run."""
    return BUILD.enabled()


# --- the modal filter of linearisation.propagate ----------------------------------------------

#: ``z[k+1] = lambda z[k] + g[k]`` for complex ``z``, ``g`` (interleaved real and imaginary parts):
#: the operations of ``scipy.signal.lfilter([1], [1, -lambda], g, zi=[lambda z[0]])`` in its order,
#: real part ``(lr zr - li zi) + gr``, imaginary part ``(lr zi + li zr) + gi`` (lfilter's products
#: by ``b = [1, 0]`` and its negations are exact).
FILTER_SOURCE = """
void panto_first_order_filter(long n, double lr, double li, const double *g, double *z) {
    double zr = z[0], zi = z[1];
    for (long k = 0; k < n; ++k) {
        double real = (lr * zr - li * zi) + g[2 * k];
        double imag = (lr * zi + li * zr) + g[2 * k + 1];
        zr = real;
        zi = imag;
        z[2 * k + 2] = zr;
        z[2 * k + 3] = zi;
    }
}

void panto_modal_accumulate(long rows, long cols, double weight, const double *z,
                            const double *vr, const double *vi, double *states) {
    for (long k = 0; k < rows; ++k) {
        double zr = z[2 * k], zi = z[2 * k + 1];
        double *row = states + k * cols;
        for (long j = 0; j < cols; ++j)
            row[j] += weight * (zr * vr[j] - zi * vi[j]);
    }
}
"""


def _bind_filter(library: ctypes.CDLL):
    function = library.panto_first_order_filter
    function.restype = None
    function.argtypes = [ctypes.c_long, ctypes.c_double, ctypes.c_double, ctypes.c_void_p,
                         ctypes.c_void_p]
    accumulate = library.panto_modal_accumulate
    accumulate.restype = None
    accumulate.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_double, ctypes.c_void_p,
                           ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    return function, accumulate


#: The library of :data:`FILTER_SOURCE` (same flags and switch as the balance).
FILTER = c_kernels.Kernel("first_order_filter", SWITCH_VARIABLE, COMPILER_FLAGS, FILTER_SOURCE,
                          _bind_filter)


@lru_cache(maxsize=1)
def _filter_function():
    return FILTER.load()


def first_order_filter(lam: complex, drive: np.ndarray, z0: complex) -> np.ndarray | None:
    """``z`` with ``z[0] = z0`` and ``z[k+1] = lam z[k] + drive[k]`` (complex, length
    ``len(drive) + 1``), bit for bit ``scipy.signal.lfilter([1], [1, -lam], drive,
    zi=[lam z0])`` after ``z0`` (checked on x86-64 with gcc and this project's SciPy,
    ``tests/test_lazy_imports.py``: a platform whose SciPy build fuses multiply-adds may differ
    in the last bit); None without a compiler or with ``PANTO_STATIC_KERNEL=0`` (the caller
    runs lfilter)."""
    functions = _filter_function() if switched_on() else None
    if functions is None:
        return None
    function = functions[0]
    g = np.ascontiguousarray(drive, dtype=complex)
    z = np.empty(len(g) + 1, dtype=complex)
    z[0] = z0
    function(len(g), float(lam.real), float(lam.imag), g.ctypes.data, z.ctypes.data)
    return z


def accumulate_mode(states: np.ndarray, z: np.ndarray, vector: np.ndarray, weight: float
                    ) -> bool:
    """``states += weight * (outer(z.real, v.real) - outer(z.imag, v.imag))`` in place, in that
    order of operations (the same values as NumPy's, without its four temporary arrays), for
    C-contiguous float64 `states` of shape ``(len(z), len(v))``; False (nothing done) without
    the compiled library or where the arrays do not fit it (the caller runs NumPy)."""
    functions = _filter_function() if switched_on() else None
    if functions is None or states.dtype != np.float64 or not states.flags.c_contiguous or \
            states.shape != (len(z), len(vector)):
        return False
    z = np.ascontiguousarray(z, dtype=complex)
    real = np.ascontiguousarray(vector.real, dtype=float)
    imag = np.ascontiguousarray(vector.imag, dtype=float)
    functions[1](len(z), len(real), float(weight), z.ctypes.data, real.ctypes.data,
                 imag.ctypes.data, states.ctypes.data)
    return True


__all__ = ["COMPILER_FLAGS", "SWITCH_VARIABLE", "FUNCTIONS", "SOURCE_CACHE_STEM", "Untranslatable",
           "python_to_c", "kernel_source", "StaticKernel", "load", "switched_on", "BUILD",
           "FILTER_SOURCE", "FILTER", "first_order_filter", "accumulate_mode"]
