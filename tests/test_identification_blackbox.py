"""Black-box state-space models (thesis 4.8): poles of known linear systems recovered from noisy
data; the output-error refinement never worsens the subspace estimate."""
import numpy as np
import pytest
from scipy import signal

from panto.fmu_src.models import Model
from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.structures.registry import identifier
from panto.identification.structures.blackbox import fit_state_space, parameter_names

PERIOD = 0.02


def steps(rng, n, low, high, hold_min, hold_max):
    values, k = np.empty(n), 0
    while k < n:
        hold = rng.integers(hold_min, hold_max)
        values[k:k + hold] = rng.uniform(low, high)
        k += hold
    return values


def simulate_discrete(a, b, c, d, u):
    """dlsim from the equilibrium at u[0] (the identified models' initial-state rule)."""
    x0 = np.linalg.solve(np.eye(len(a)) - a, b @ u[0])
    return signal.dlsim((a, b, c, d, PERIOD), u, x0=x0)[1]


def continuous_modes(eigenvalues):
    s = eigenvalues[eigenvalues.imag > 0]
    order = np.argsort(np.abs(s))
    return np.abs(s[order]) / (2 * np.pi), (-s.real / np.abs(s))[order]


def identified_modes(result):
    modes = result.details["modes"]
    return (np.array([m["frequency_hz"] for m in modes]), np.array([m["damping"] for m in modes]))


def total_cost(fits):
    return sum((1 - f / 100) ** 2 for f in fits.values())


def test_random_fourth_order_mimo_system():
    rng = np.random.default_rng(4)
    frequencies, dampings = np.array([1.2, 5.5]), np.array([0.08, 0.15])
    blocks = [np.array([[0, 1], [-(2 * np.pi * f) ** 2, -2 * z * 2 * np.pi * f]])
              for f, z in zip(frequencies, dampings)]
    a_c = np.block([[blocks[0], np.zeros((2, 2))], [np.zeros((2, 2)), blocks[1]]])
    mix = rng.standard_normal((4, 4))  # hide the modal structure
    a_c = mix @ a_c @ np.linalg.inv(mix)
    b_c, c_c, d_c = rng.standard_normal((4, 2)), rng.standard_normal((2, 4)), 0.1 * rng.standard_normal((2, 2))
    a, b, c, d, _ = signal.cont2discrete((a_c, b_c, c_c, d_c), PERIOD, method="zoh")
    n = 4000
    u = np.column_stack([steps(rng, n, -1, 1, 3, 30), steps(rng, n, -1, 1, 5, 50)]) + [2.0, -3.0]
    y = simulate_discrete(a, b, c, d, u) + [10.0, 0.5]
    y_noisy = y + 0.03 * y.std(axis=0) * rng.standard_normal(y.shape)
    y_noisy[100:130, 1] = np.nan  # dropouts are left out
    data = IdentificationData(np.arange(n) * PERIOD, u, y_noisy, ("u1", "u2"), ("y1", "y2"))
    result = fit_state_space(data, 4)
    f, z = identified_modes(result)
    np.testing.assert_allclose(f, frequencies, rtol=0.01)
    np.testing.assert_allclose(z, dampings, atol=0.01)
    floor = 100 * (1 - 0.03)
    assert all(v > floor - 0.5 for v in result.fit.values()), result.fit
    assert total_cost(result.fit) <= total_cost(result.details["fit_subspace"]) + 1e-12
    assert result.n_free == len(parameter_names(4, ("u1", "u2"), ("y1", "y2"))) == 26
    # the identified model reproduces the noise-free response on fresh inputs (validation)
    u_val = np.column_stack([steps(rng, 1500, -1, 1, 3, 30), steps(rng, 1500, -1, 1, 5, 50)]) + [2.0, -3.0]
    y_val = simulate_discrete(a, b, c, d, u_val) + [10.0, 0.5]
    val = IdentificationData(np.arange(1500) * PERIOD, u_val, y_val, ("u1", "u2"), ("y1", "y2"))
    assert all(v > 97.0 for v in result.fit_on(val, ("y1", "y2")).values())
    # the physical matrices reproduce the simulator
    details = result.details
    a_i, b_i, c_i, d_i = (np.array(details[k]) for k in "ABCD")
    du = u_val - np.array(details["u_ref"])
    y_mat = simulate_discrete(a_i, b_i, c_i, d_i, du) + np.array(details["y_ref"])
    np.testing.assert_allclose(y_mat, result.simulate(val), atol=1e-8 * np.abs(y_val).max())


@pytest.fixture(scope="module")
def pantograph_data():
    """The linearised pantograph (eta, p -> F_c, y_cb) at 50 Hz, APRBS inputs, 2 % noise."""
    rng = np.random.default_rng(2)
    lin = Model("Pantograph").linearise(2.0, 4.0)
    rows = [2, 0]
    a, b, c, d, _ = signal.cont2discrete((lin.A, lin.B, lin.C[rows], lin.D[rows]), PERIOD, method="zoh")
    n = 4000
    du = np.column_stack([steps(rng, n, -0.02, 0.02, 3, 40), steps(rng, n, -0.4, 0.4, 10, 80)])
    y = simulate_discrete(a, b, c, d, du) + lin.y0[rows]
    y += 0.02 * y.std(axis=0) * rng.standard_normal(y.shape)
    data = IdentificationData(np.arange(n) * PERIOD, du + lin.u0, y, ("eta", "p"), ("F_c", "y_cb"))
    return data, continuous_modes(lin.eigenvalues)


def test_order_six_recovers_the_linearised_pantographs_modes(pantograph_data):
    data, (frequencies, dampings) = pantograph_data
    result = identifier("blackbox-6").identify(data)
    f, z = identified_modes(result)
    np.testing.assert_allclose(f, frequencies, rtol=0.03)  # 3.05, 11.6, 15.4 Hz
    np.testing.assert_allclose(z, dampings, atol=0.05)
    assert total_cost(result.fit) <= total_cost(result.details["fit_subspace"]) + 1e-12
    assert all(v > 97.5 for v in result.fit.values())


def test_order_four_keeps_the_two_dominant_modes(pantograph_data):
    data, (frequencies, dampings) = pantograph_data
    result = identifier("blackbox-4").identify(data)
    f, z = identified_modes(result)
    np.testing.assert_allclose(f, frequencies[:2], rtol=0.01)  # the 15 Hz mode is weakest
    np.testing.assert_allclose(z, dampings[:2], atol=0.01)
    assert total_cost(result.fit) <= total_cost(result.details["fit_subspace"]) + 1e-12


def test_refinement_improves_a_poor_subspace_estimate(pantograph_data):
    data, _ = pantograph_data
    rough = fit_state_space(data, 4, horizon=5, refine=False)  # short horizon: biased
    refined = fit_state_space(data, 4, horizon=5)
    assert total_cost(refined.fit) <= total_cost(rough.fit)
    assert refined.details["fit_subspace"] == rough.fit


def test_bad_order_and_too_few_samples():
    t = np.arange(50) * PERIOD
    data = IdentificationData(t, np.sin(t)[:, None], np.cos(t)[:, None], ("u",), ("y",))
    with pytest.raises(IdentificationError, match="order"):
        fit_state_space(data, 0)
    with pytest.raises(IdentificationError, match="too few"):
        fit_state_space(data, 4)


def test_a_mode_at_one_starts_at_rest_instead_of_failing():
    """An integrator mode (pole exactly at 1) has no steady state for a constant input: the
    filter then starts at rest on the input's deviation (a held-out diagnosis case crashed here
    with a singular matrix); the same for a second-order block with a root at 1."""
    from panto.identification.structures.blackbox import _steady_first, _steady_pair

    x = np.array([2.0, 2.0, 3.0, 3.0, 3.0])
    assert np.allclose(_steady_first(1.0, x), [0.0, 0.0, 0.0, 1.0, 2.0])
    # a stable mode still starts in its steady state: 1 / (1 - 0.5) times the input
    assert np.allclose(_steady_first(0.5, x)[:3], [4.0, 4.0, 4.0])
    first, second = _steady_pair([1.0, -1.5, 0.5], x)  # roots 1 and 0.5
    assert np.allclose(first, [0.0, 0.0, 0.0, 1.0, 2.5]) and np.allclose(second[1:], first[:-1])
    # a root at 1 whose coefficients' sum rounds to 1e-17 (a saturated tanh-bounded block)
    det = 0.1
    trace = (1.0 + det) * np.tanh(25.0)
    assert 0.0 < abs(1.0 - trace + det) < 1e-15
    first, second = _steady_pair([1.0, -trace, det], x)
    assert np.max(np.abs(first)) < 10.0 and first[0] == 0.0 and second[0] == 0.0


def test_the_closed_form_steady_start_is_scipys():
    """The black box's filters started in the steady state in closed form (blackbox.py
    ``_steady_pair``, ``_steady_first``) against SciPy's own path, ``lfilter`` from
    ``lfilter_zi`` (a linear solve), for random stable blocks: the same to rounding."""
    from panto.identification.structures.blackbox import _steady_first, _steady_pair

    rng = np.random.default_rng(3)
    for _ in range(50):
        x = 3.0 * rng.normal() + rng.normal(size=400)
        radius, angle = rng.uniform(0.1, 0.99), rng.uniform(0.0, np.pi)
        a = [1.0, -2.0 * radius * np.cos(angle), radius ** 2]
        for b, mine in zip(([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]), _steady_pair(a, x)):
            theirs, _ = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
            assert np.max(np.abs(mine - theirs)) < 1e-12 * np.max(np.abs(theirs))
        pole = rng.uniform(-0.99, 0.99)
        theirs, _ = signal.lfilter([0.0, 1.0], [1.0, -pole], x,
                                   zi=signal.lfilter_zi([0.0, 1.0], [1.0, -pole]) * x[0])
        assert np.max(np.abs(_steady_first(pole, x) - theirs)) < 1e-12 * np.max(np.abs(theirs))
