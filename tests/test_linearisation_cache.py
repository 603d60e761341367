"""The linearisation's remembered equilibria (identification/structures/linearisation.py,
``_equilibrium``): a parameter set that differs only where the model at rest does not look (the
dampings) reuses an equilibrium, and must give bit for bit what a fresh solve gives; any other
change must solve afresh."""
from __future__ import annotations

import numpy as np
import pytest

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
