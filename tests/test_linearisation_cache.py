"""The linearisation's remembered equilibria (identification/structures/linearisation.py,
``_equilibrium``): a parameter set that differs only where the model at rest does not look (the
dampings) reuses an equilibrium, and must give bit for bit what a fresh solve gives; any other
change must solve afresh."""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationError
from panto.identification.structures import linearisation as lin

INPUTS = [1.8, 4.0]  # eta [m], p [bar]


def _fresh(p):
    lin._EQUILIBRIA.clear()
    return lin.linearise(p, INPUTS)


@pytest.fixture(scope="module")
def parameters():
    names, vector = lin.parameter_defaults()
    rng = np.random.default_rng(7)
    return names, [vector * (1.0 + rng.normal(0.0, 0.03, vector.size)) for _ in range(3)]


def test_the_dampings_do_not_move_the_equilibrium(parameters):
    """Physics, by the solver itself: at rest no damping force acts, so a damping changed by
    half leaves the solved equilibrium exactly where it was."""
    names, sets = parameters
    statics = set(lin.static_functions()["static_parameters"])
    for damping in ("c1", "c2", "c3", "c_c"):
        assert lin.INDEX[damping] not in statics
    for p in sets:
        q = p.copy()
        q[lin.INDEX["c2"]] *= 1.5
        assert np.array_equal(lin.solve_equilibrium(p, INPUTS), lin.solve_equilibrium(q, INPUTS))


@pytest.mark.parametrize("name", ["c1", "c_c", "k", "m2", "k_p"])
def test_a_remembered_equilibrium_equals_a_fresh_solve_bit_for_bit(parameters, name):
    names, sets = parameters
    for p in sets:
        base = _fresh(p)
        q = p.copy()
        q[lin.INDEX[name]] *= 1.0 + 1e-6  # a finite-difference column
        lin.linearise(p, INPUTS)
        remembered = lin.linearise(q, INPUTS)
        fresh = _fresh(q)
        assert all(np.array_equal(a, b) for a, b in zip(remembered, fresh)), name
        # the change is seen: a damping in A only, a static parameter in the equilibrium too
        assert not np.array_equal(remembered[0], base[0])
        moved = not np.array_equal(remembered[4], base[4])
        assert moved == (lin.INDEX[name] in lin.static_functions()["static_parameters"]), name


def _previous_newton(p, u, q, tolerance):
    """Newton's method as it was before the balance was bound to `p` and `u`: the kernel's
    balance (or the Python one) afresh at every point, ``np.linalg.solve``, ``dr/dq`` at the
    equilibrium balanced once more."""
    kernel = lin.compiled()

    def balance(q):
        n = 3
        out = None if kernel is None else kernel._call("balance", p, q, u, n + n * n)
        if out is not None:
            return out[:n].copy(), out[n:].reshape(n, n).copy()
        r, drdq = lin.static_functions()["balance"](p, q, u, lin.linkage_angles(p, q))
        return np.array(r, float).ravel(), np.array(drdq, float)

    r, jac = balance(q)
    scale = max(1.0, float(np.max(np.abs(r))), abs(p[lin.INDEX["k_p"]] * u[1]))
    for _ in range(50):
        step = np.linalg.solve(jac, -r)
        lam, norm = 1.0, lin._norm(r)
        while True:
            try:
                r_new, jac_new = balance(q + lam * step)
                if lin._norm(r_new) < norm or lam < 1e-3:
                    break
            except IdentificationError:
                pass
            lam *= 0.5
            if lam < 1e-4:
                raise IdentificationError("Newton step left the admissible configurations")
        q, r, jac = q + lam * step, r_new, jac_new
        if all(abs(x) <= tolerance * scale for x in r.tolist()) and \
                all(abs(lam * s) < 1e-9 for s in step.tolist()):
            return q, balance(q)[1]
    raise IdentificationError("Newton's method did not converge to an equilibrium")


def test_linear_system_equals_the_previous_computation_bit_for_bit(monkeypatch):
    """``PhysicalLinear.linear_system`` with its shortcuts (the operating point and the
    signals remembered, the balance bound to one parameter set, numpy's solve without its
    wrapper, Newton's last ``dr/dq`` kept) against the computation before them, nothing
    remembered, over random admissible parameters, finite-difference neighbours and input
    delays: every matrix and every refusal the same."""
    from panto.identification.estimation.base import IdentificationData
    from panto.identification.structures import physical

    time = np.arange(0.0, 8.0, 0.02)
    eta = 1.8 + 0.03 * np.sin(2 * np.pi * 0.7 * time)
    p = 4.0 + 0.4 * np.sin(2 * np.pi * 0.23 * time + 0.4)
    data = IdentificationData(time, np.column_stack([eta, p]), np.zeros((len(time), 2)),
                              ("eta", "p"), ("F_c", "y_cb"))
    structure = physical.PhysicalLinear(outputs=("F_c", "y_cb"))
    nominal, rng = structure.nominal(), np.random.default_rng(11)
    draws = []
    for k in range(24):
        spread = (0.03, 0.3, 1.5)[k % 3]
        draw = {n: float(np.clip(nominal[n] * np.exp(rng.normal(0.0, spread)),
                                 *physical.BOUNDS[n])) for n in physical.TABLE_4_1}
        draw["eta_delay"] = (0.0, 0.004, -0.01)[k % 3] if k % 4 == 0 else 0.0
        draws += [draw] + [dict(draw, **{n: draw[n] * (1.0 + 1e-6)}) for n in ("c2", "k", "m_c")]

    def outcome(parameters):
        try:
            return structure.linear_system(parameters, data)
        except IdentificationError as error:
            return str(error)

    lin._EQUILIBRIA.clear()
    fast = [outcome(d) for d in draws]
    monkeypatch.setattr(lin, "_newton", _previous_newton)
    monkeypatch.setattr(lin, "_linear_solve", np.linalg.solve)
    previous = []
    for d in draws:
        lin._EQUILIBRIA.clear()
        physical._OPERATING_POINTS.clear()
        previous.append(outcome(d))
    assert sum(not isinstance(f, str) for f in fast) > 40
    assert any(isinstance(f, str) for f in fast)  # refusals are compared too
    for f, p in zip(fast, previous):
        assert type(f) is type(p)
        assert f == p if isinstance(f, str) else all(np.array_equal(a, b) for a, b in zip(f, p))


def test_the_small_solve_is_numpys_bit_for_bit():
    """``_linear_solve`` calls ``np.linalg.solve``'s own gufunc: the same bits, and a singular
    matrix raises as there."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        matrix = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6, 6, (3, 3))
        for right in (rng.normal(size=3), rng.normal(size=(3, 8))):
            assert np.array_equal(lin._linear_solve(matrix, right), np.linalg.solve(matrix, right))
    with pytest.raises(np.linalg.LinAlgError, match="Singular matrix"):
        lin._linear_solve(np.ones((3, 3)), np.ones(3))
