"""Online (receding-horizon) design for the pantograph rig (issue 7; thesis sections 5.4-5.5)."""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.pantograph_online import (
    OnlineDesigner,
    design_online_step,
    run_online_design,
)
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph, PressureLag

CONSTRAINTS = RigInputConstraints(pressure_lag=PressureLag(0.22, 0.02))
FREE = ("m_c", "c_c", "k_c", "k_p", "c1", "m1")


@pytest.fixture(scope="module")
def designer() -> OnlineDesigner:
    model = LinearisedPantograph("physical-linear", free=FREE, length=300,
                                 pressure_lag=CONSTRAINTS.pressure_lag)
    return OnlineDesigner(model, CONSTRAINTS, horizon=20, memory=150)


def _past(rng, n=60):
    motor = np.concatenate([[0.0], np.cumsum(rng.uniform(-0.005, 0.005, n))])
    demand = np.concatenate([[4.0], 4.0 + rng.uniform(-0.3, 0.3, n)])
    return motor, demand


def test_horizon_matrices_equal_the_convolution_model(designer):
    """Free response + block-Toeplitz part = the FFT convolution of the whole input (two
    independent paths), for the sensitivities and the contact force; the gradient of the
    criterion equals central differences."""
    rng = np.random.default_rng(0)
    motor, demand = _past(rng)
    speed = (motor[-1] - motor[-2]) / CONSTRAINTS.sample_period
    state = (motor[-1], speed)
    past = np.stack([2.0 + motor, demand], axis=-1)
    x = np.concatenate([rng.uniform(-5, 5, designer.n_blocks),
                        rng.uniform(3.6, 5.0, designer.n_blocks)])
    future_motor, future_demand = designer.decode(x, state)
    whole = np.concatenate([past, np.stack([2.0 + future_motor, future_demand], axis=-1)])
    y, psi = designer.model.sensitivities(None, whole)
    psi_free, force_free = designer.free_response(past)
    h = designer.horizon
    offset = np.column_stack([state[0] + CONSTRAINTS.sample_period * speed * np.arange(1, h + 1),
                              np.full(h, -4.0)])
    base = np.einsum("kotji,ji->kot", designer.toeplitz, offset)
    mine = psi_free + np.einsum("kotv,v->kot", designer.gradient_map, x) + base
    expected = psi[-h:] * designer.scale
    assert np.max(np.abs(mine - expected)) <= 1e-9 * np.max(np.abs(expected))
    force = force_free + designer.force_map @ x + np.einsum("kji,ji->k", designer.force_toeplitz,
                                                             offset)
    assert np.allclose(force, designer.model.simulate(whole, ["F_c"])[-h:, 0], atol=1e-8)
    prior = 1e-3 * np.eye(len(FREE))
    _, gradient = designer.cost(x, psi_free, base, prior)
    numeric = [(designer.cost(x + 1e-6 * e, psi_free, base, prior)[0]
                - designer.cost(x - 1e-6 * e, psi_free, base, prior)[0]) / 2e-6
               for e in np.eye(x.size)]
    assert np.allclose(gradient, numeric, rtol=1e-4, atol=1e-6 * np.max(np.abs(gradient)))


def test_closed_loop_meets_every_rig_limit_and_gains_information(designer):
    """Every applied input meets amplitude, speed, acceleration, pressure range and contact
    force; each step is no worse than its warm start; the run excites both inputs."""
    motor, demand, times = run_online_design(designer, 120)
    c = CONSTRAINTS
    assert max(c.violations(motor, demand).values()) <= 0.0
    force = designer.model.simulate(np.stack([2.0 + motor, demand], axis=-1), ["F_c"])[:, 0]
    # the constraint holds on the model up to the memory truncation of older inputs
    assert force.min() >= c.minimum_contact_force - 0.05
    assert np.ptp(motor) > 0.02 and np.ptp(demand) > 0.5
    assert len(times) == 119


def test_step_never_worse_than_warm_start_and_plan_is_feasible(designer):
    rng = np.random.default_rng(4)
    motor, demand = _past(rng, 30)
    step = design_online_step(designer, motor, demand)
    assert step.value >= step.start_value - 1e-9
    c = CONSTRAINTS
    plan_motor = np.concatenate([motor, step.motor_position])
    plan_demand = np.concatenate([demand, step.pressure_demand])
    # the plan continues the past within the limits and ends at rest (terminal constraint)
    v = np.diff(plan_motor[-(designer.horizon + 1):]) / c.sample_period
    assert np.all(np.abs(v) <= c.motor_speed + 1e-9) and abs(v[-1]) <= 1e-9
    assert np.all(np.abs(np.diff(v)) / c.sample_period <= c.motor_acceleration + 1e-6)
    assert plan_demand.min() >= c.pressure_min and plan_demand.max() <= c.pressure_max
