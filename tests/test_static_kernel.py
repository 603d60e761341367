"""The pantograph at rest compiled (identification/structures/static_kernel.py): the C translation
of the lambdified balance and linearisation must give bit for bit what the Python functions give
(two independent paths: CPython/NumPy scalar arithmetic and the compiled C), Newton's equilibria
and the linearisation must be the same with the kernel on and off, and where the Python path
raises (the linkage cannot close) the compiled path must raise the same way."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from panto.fmu_src import c_kernels
from panto.identification.estimation.base import IdentificationError
from panto.identification.structures import linearisation as lin
from panto.identification.structures import static_kernel

pytestmark = pytest.mark.skipif(c_kernels.find_compiler() is None, reason="no C compiler")

INPUTS = [1.8, 4.0]  # eta [m], p [bar]


@pytest.fixture(scope="module")
def kernel():
    found = lin.compiled()
    assert found is not None, "the static kernel did not build"
    return found


def _python_balance(p, q, u):
    r, drdq = lin.static_functions()["balance"](p, q, u, lin.linkage_angles(p, q))
    return np.array(r, float).ravel(), np.array(drdq, float)


def _python_linear(p, q, u):
    return [np.array(a, float) for a in
            lin.static_functions()["linear"](p, q, u, lin.linkage_angles(p, q))]


def test_the_compiled_balance_and_linearisation_equal_python_bit_for_bit(kernel):
    """Random parameter sets (30 % spread on half the parameters), configurations around the
    equilibrium and inputs, contact on and off: every value identical (balance, linearisation,
    cross-bar height, the linkage's reach on a grid of the lower-arm angle)."""
    names, p0 = lin.parameter_defaults()
    q0 = lin.solve_equilibrium(p0, INPUTS)
    rng = np.random.default_rng(3)
    compared = 0
    for _ in range(300):
        p = p0 * (1.0 + 0.3 * rng.standard_normal(p0.size) * (rng.random(p0.size) < 0.5))
        p[lin.INDEX["unilateral_contact"]] = float(rng.random() < 0.5)
        q = q0 + rng.standard_normal(3) * [0.05, 0.01, 0.02]
        u = [INPUTS[0] + 0.05 * rng.standard_normal(), INPUTS[1] + rng.standard_normal()]
        try:
            expected_balance, expected_linear = _python_balance(p, q, u), _python_linear(p, q, u)
        except (IdentificationError, ArithmeticError, ValueError):
            continue
        balance, linear = kernel.balance(p, q, u), kernel.linear(p, q, u)
        assert all(np.array_equal(a, b) for a, b in zip(balance, expected_balance))
        assert len(linear) == 7
        assert all(np.array_equal(a, b) for a, b in zip(linear, expected_linear))
        f = lin.static_functions()
        assert kernel.height(p, q) == f["height"](p, q, lin.linkage_angles(p, q))
        grid = q[0] + np.linspace(-0.5, 0.5, 11)
        reach = kernel.reach_grid(p, q, grid)
        assert np.array_equal(reach, [f["reach"](p, [phi, q[1], q[2]]) for phi in grid])
        compared += 1
    assert compared > 150, compared


def test_equilibrium_and_linearisation_are_the_same_with_the_kernel_off(kernel, monkeypatch):
    names, p0 = lin.parameter_defaults()
    rng = np.random.default_rng(5)
    sets = [p0 * (1.0 + rng.normal(0.0, 0.05, p0.size)) for _ in range(3)]

    def solve_all():
        lin._EQUILIBRIA.clear()
        return [lin.linearise(p, INPUTS) for p in sets] + [lin.initial_guess(p0, INPUTS)]

    on = solve_all()
    monkeypatch.setenv(static_kernel.SWITCH_VARIABLE, "0")
    assert lin.compiled() is None
    off = solve_all()
    for a, b in zip(on[:-1], off[:-1]):
        assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert np.array_equal(on[-1], off[-1])


def test_where_the_linkage_cannot_close_the_python_path_raises(kernel):
    """Beyond the linkage's reach the kernel declines (None) and the balance raises as before."""
    names, p0 = lin.parameter_defaults()
    far = [3.0, 0.0, INPUTS[0]]  # the lower arm nearly upright: the upper arm cannot reach
    with pytest.raises(IdentificationError, match="cannot close"):
        lin.linkage_angles(p0, far)
    assert kernel.balance(p0, far, INPUTS) is None
    with pytest.raises(IdentificationError, match="cannot close"):
        lin._balance_at(p0, INPUTS, kernel)(far)
    assert kernel.balance(p0[:-1], far, INPUTS) is None  # wrong length: the Python path


def test_the_translation_keeps_python_operations_in_order():
    """``x**2`` as ``pow``, true division of integer constants, the conditional's branch, the
    unpacked list arguments and the row-major outputs."""
    source = ("def f(_Dummy_1, s):\n    [a, b] = _Dummy_1\n    x0 = a**2\n"
              "    return [[x0 + 1/2*b, ((0) if (a > b) else (s*(b - a)))]]\n")
    text, count = static_kernel.python_to_c(source, "f")
    assert count == 2
    assert "pow(v_a, (2.0))" in text and "((1.0) / (2.0))" in text
    assert "const double *v__Dummy_1" in text and "double v_s" in text
    assert "? (0.0) : (v_s * (v_b - v_a))" in text
    with pytest.raises(static_kernel.Untranslatable):
        static_kernel.python_to_c("def f(a):\n    return a[0]\n", "f")


def test_a_cache_that_cannot_be_written_builds_in_a_private_folder(tmp_path, monkeypatch):
    """`c_kernels.build_library` with its cache under a plain file (no folder can be made there,
    whoever runs the test): the library is built elsewhere and works; without a compiler, None."""
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(c_kernels.CACHE_VARIABLE, str(blocker / "cache"))
    source = "double panto_test_twice(double x) { return 2.0 * x; }\n"
    library = c_kernels.build_library(source, "twice")
    assert library is not None
    library.panto_test_twice.restype = ctypes.c_double
    library.panto_test_twice.argtypes = [ctypes.c_double]
    assert library.panto_test_twice(1.25) == 2.5
    assert c_kernels.build_library(source + "\n", "twice", find=lambda: None) is None
