"""The Python path integrates through smooth stretches of the input and restarts at its steps.

Independent path: :func:`scipy.integrate.solve_ivp` on the model's derivatives with the input
written as a function of time by hand, restarted exactly where the input jumps.
"""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from panto.fmu_src.models import Model
from panto.fmu_src.simulation import SolverOptions, _smooth_stretches, simulate_model

TOLERANCES = {"rtol": 1e-10, "atol": 1e-12}


def _reference(model, time, pieces, x0):
    """States at `time` from solve_ivp over each (start, end, input function) piece."""
    p, numeric, states, x = model.parameters.vector(), model.numeric, [], np.asarray(x0, float)
    for start, end, inputs_at in pieces:
        inside = time[(time >= start) & (time <= end)]
        sol = solve_ivp(lambda t, z: numeric.derivatives(p, z, inputs_at(t)), (start, end), x,
                        t_eval=inside, method="DOP853", **TOLERANCES)
        states += list(sol.y.T if not states else sol.y.T[1:])
        x = sol.y[:, -1]
    return np.array(states)


def test_a_held_step_is_a_restart_and_the_states_follow_the_two_constant_pieces():
    model = Model("TwoMass")
    time = np.linspace(0.0, 1.0, 201)
    eta = np.where(time < 0.5, 0.0, 0.01)  # held: 0 on [0, 0.5), 0.01 from the sample at 0.5 on
    x0 = model.equilibrium(0.0, 4.0)
    assert _smooth_stretches(time, np.column_stack([eta, np.full_like(time, 4.0)]), "hold") \
        == [(0, 100), (100, 200)]
    response = simulate_model(model, time, {"eta": eta, "p": 4.0}, initial_state=x0,
                              interpolation="hold",
                              solver=SolverOptions(method="DOP853", **TOLERANCES))
    states = np.column_stack([response[name] for name in model.state_names])
    expected = _reference(model, time, [(0.0, 0.5, lambda t: np.array([0.0, 4.0])),
                                        (0.5, 1.0, lambda t: np.array([0.01, 4.0]))], x0)
    assert np.ptp(states[:, 1]) > 1e-3  # the step really moves the head
    np.testing.assert_allclose(states, expected, atol=1e-8 * np.max(np.abs(expected)))


def test_a_sampled_ramp_is_one_stretch_and_equals_the_affine_input():
    model = Model("TwoMass")
    time = np.linspace(0.0, 0.8, 401)
    rate = 0.05  # m/s
    x0 = model.equilibrium(0.0, 4.0)
    u = np.column_stack([rate * time, np.full_like(time, 4.0)])
    assert _smooth_stretches(time, u, "linear") == [(0, 400)]  # rounding does not cut it
    response = simulate_model(model, time, {"eta": rate * time, "p": 4.0}, initial_state=x0,
                              solver=SolverOptions(method="DOP853", **TOLERANCES))
    states = np.column_stack([response[name] for name in model.state_names])
    expected = _reference(model, time, [(0.0, 0.8, lambda t: np.array([rate * t, 4.0]))], x0)
    np.testing.assert_allclose(states, expected, atol=1e-8 * np.max(np.abs(expected)))


@pytest.mark.parametrize("interpolation", ["linear", "hold"])
def test_a_kink_or_a_change_every_sample_restarts_at_every_sample(interpolation):
    time = np.linspace(0.0, 1.0, 11)
    u = np.column_stack([np.sin(7 * time), np.full_like(time, 4.0)])
    assert _smooth_stretches(time, u, interpolation) == [(k, k + 1) for k in range(10)]
