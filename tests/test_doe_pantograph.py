"""Design of experiments for the pantograph rig (issue 7, part 2; thesis section 5.5)."""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure
from panto.identification.design.constraints import RigInputConstraints, conventional_inputs
from panto.identification.design.pantograph import (
    DesignOptions,
    build_inputs,
    design_pantograph_experiment,
    model_inputs,
)
from panto.identification.design.discrimination import (
    EffectModel,
    design_discrimination,
    simulate_friction,
)
from panto.identification.design.profiles import write_design_profile
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph, PressureLag

CONSTRAINTS = RigInputConstraints(pressure_lag=PressureLag(0.22, 0.02))
FREE = ("m1", "m2", "k1", "k2", "c1", "c2", "p_gain", "F_0")
N = 750  # 15 s at 50 Hz


@pytest.fixture(scope="module")
def two_mass() -> LinearisedPantograph:
    return LinearisedPantograph("two-mass", free=FREE, length=N,
                                pressure_lag=CONSTRAINTS.pressure_lag)


@pytest.fixture(scope="module")
def design(two_mass):
    return design_pantograph_experiment(two_mass, CONSTRAINTS,
                                        options=DesignOptions(population=16, generations=15))


def _data(structure, inputs: np.ndarray, outputs: np.ndarray) -> IdentificationData:
    time = np.arange(len(inputs)) * CONSTRAINTS.sample_period
    return IdentificationData(time, inputs, outputs, ("eta", "p"), structure.output_names)


def _random_inputs(rng, count: int = 5) -> np.ndarray:
    c = CONSTRAINTS
    motor = rng.uniform(c.motor_min, c.motor_max, (count, 150)) * rng.uniform(0, 0.3, (count, 1))
    pressure = rng.uniform(3.6, 5.0, (count, 30))
    return model_inputs(*build_inputs(motor, pressure, c, N), c)


@pytest.mark.parametrize("name", ["two-mass", "physical-linear"])
def test_convolution_model_equals_structure_simulation(name):
    """Markov-parameter convolution and sensitivities agree with the structure's own free run
    (exact discretisation + recursion) and its finite differences: two independent paths."""
    from panto.identification.structures.physical import PhysicalLinear

    model = LinearisedPantograph(name, length=400, pressure_lag=None,
                                 free=None if name == "two-mass" else ("m_c", "k_c", "k_p"))
    structure = OscillatorStructure(2) if name == "two-mass" else PhysicalLinear(
        operating_point="first")
    u = _random_inputs(np.random.default_rng(3), 1)[0, :400]
    data = _data(structure, u, np.zeros((400, 2)))
    y, psi = model.sensitivities(None, u)
    assert np.allclose(y, structure.simulate(model.parameters, data), atol=1e-8, rtol=1e-9)
    for i, parameter in enumerate(model.parameter_names[:3]):
        h = 1e-4 * abs(model.parameters[parameter])
        up, down = (structure.simulate(model.parameters | {parameter: model.parameters[parameter]
                                                           + s}, data) for s in (h, -h))
        scale = np.max(np.abs(psi[:, :, i]), axis=0)
        assert np.all(np.max(np.abs((up - down) / (2 * h) - psi[:, :, i]), axis=0)
                      <= 1e-4 * scale)


def test_pressure_lag_is_the_sampled_first_order_response():
    lag = PressureLag(0.3, 0.04)
    demand = np.full(200, 5.0)
    demand[0] = 4.0
    p = lag.apply(demand, 0.02, 4.0)
    t = np.arange(200) * 0.02
    # demand steps at t = 0.02; seen after the 0.04 s delay, i.e. from t = 0.06 on
    expected = 4.0 + np.where(t >= 0.06, 1.0 - np.exp(-(t - 0.06) / 0.3), 0.0)
    assert np.allclose(p, expected, atol=1e-12)


def test_every_built_input_meets_the_rig_limits():
    """Any levels (even outside the range) give inputs within amplitude, speed, acceleration
    and pressure limits, starting at rest."""
    rng = np.random.default_rng(0)
    c = CONSTRAINTS
    motor, demand = build_inputs(rng.uniform(-0.5, 0.5, (20, 150)), rng.uniform(0, 9, (20, 30)),
                                 c, N)
    for m, d in zip(motor, demand):
        assert max(c.violations(m, d).values()) <= 0.0
    assert np.all(motor[:, 0] == 0.0) and np.all(demand[:, 0] == c.pressure_start)
    # the limits are reached, not trivially met by a tiny signal
    speed = np.abs(np.diff(motor, axis=1)).max() / c.sample_period
    assert speed > 0.9 * c.motor_speed


def test_design_meets_constraints_and_loads_as_a_rig_profile(design, two_mass, tmp_path):
    from panto.rig.profiles import load_profile, render_profile

    assert max(design.constraints.violations(design.motor_position,
                                              design.pressure_demand).values()) <= 0.0
    force = two_mass.simulate(model_inputs(design.motor_position, design.pressure_demand,
                                           CONSTRAINTS), ["F_c"])
    assert force.min() >= CONSTRAINTS.minimum_contact_force - 1e-9
    path, table = write_design_profile(design.motor_position, design.pressure_demand,
                                       CONSTRAINTS, tmp_path, name="test_design")
    profile = load_profile(path)
    rendered = render_profile(profile)
    assert profile.duration == pytest.approx(N * CONSTRAINTS.sample_period)
    assert np.allclose(rendered.motor_demand[::10], design.motor_position, atol=1e-12)
    assert np.allclose(rendered.pressure_demand[::10], design.pressure_demand, atol=1e-12)
    # the rig's 5 mm per 4 ms limiter never acts on the design
    assert np.max(np.abs(np.diff(rendered.motor_demand[::2]))) <= 0.005


def test_design_has_lower_predicted_covariance_than_aprbs(design):
    assert design.value > design.conventional_value  # log det M (relative parameters)
    assert np.linalg.det(design.covariance) < np.linalg.det(design.conventional_covariance)


def test_fitted_covariance_smaller_on_designed_run(design, two_mass):
    """Monte-Carlo with the structure as the plant (noise only): least-squares fits of the
    designed run report a smaller covariance (determinant) than those of the APRBS run, and
    recover the true parameters."""
    from panto.identification.estimation.least_squares import fit_least_squares

    structure = OscillatorStructure(2)
    truth = two_mass.parameters
    sigma = np.sqrt(two_mass.noise_variance_default())
    rng = np.random.default_rng(11)
    logdets = {}
    for name, (motor, demand) in {"designed": (design.motor_position, design.pressure_demand),
                                  "aprbs": (design.conventional_motor_position,
                                            design.conventional_pressure_demand)}.items():
        pressure = CONSTRAINTS.pressure_lag.apply(demand, CONSTRAINTS.sample_period, 4.0)
        u = np.column_stack([2.0 + motor, pressure])
        clean = structure.simulate(truth, _data(structure, u, np.zeros((N, 2))))
        values = []
        for _ in range(2):
            noisy = clean + sigma * rng.standard_normal(clean.shape)
            start = {k: truth[k] * 1.05 for k in FREE}
            result = fit_least_squares(structure, _data(structure, u, noisy), free=FREE,
                                       initial=start)
            estimate = np.array([result.parameters[k] for k in FREE])
            std = np.sqrt(np.diag(result.covariance))
            assert np.all(np.abs(estimate - [truth[k] for k in FREE]) <= 5 * std + 1e-9)
            values.append(np.linalg.slogdet(result.covariance)[1])
        logdets[name] = np.mean(values)
    assert logdets["designed"] < logdets["aprbs"]


def test_population_friction_simulation_equals_structure():
    structure = OscillatorStructure(2, friction=True)
    values = structure.values({"F_f1": 5.0, "F_f2": 0.0})
    u = _random_inputs(np.random.default_rng(5), 3)[:, :300]
    together = simulate_friction(structure, values, u, 0.02)
    alone = structure.simulate_inputs(values, np.column_stack([u[2], np.ones(300)]), 0.02)
    assert np.allclose(together[2], alone, atol=1e-9)


def test_discrimination_design_shows_friction_more_than_aprbs():
    n = 500
    model = LinearisedPantograph("two-mass", free=FREE, length=n,
                                 pressure_lag=CONSTRAINTS.pressure_lag)
    effect = EffectModel("F_f1", model, 5.0)
    result = design_discrimination(effect, CONSTRAINTS,
                                   options=DesignOptions(population=12, generations=8))
    assert result.value_t > result.conventional_value_t > 0
    assert result.plain >= result.value_t  # re-fitting the nominal model can only absorb
    assert max(CONSTRAINTS.violations(result.motor_position, result.pressure_demand).values()) <= 0


def test_conventional_input_is_the_conditioned_aprbs():
    motor, demand = conventional_inputs(N, CONSTRAINTS)
    assert motor.shape == demand.shape == (N,)
    assert abs(motor[0]) < 1e-3  # the conditioning fades in from rest
    assert np.ptp(motor) > 0.01 and np.ptp(demand) > 0.2


def test_cli_writes_profile_and_tables(tmp_path):
    from panto.cli import main
    from panto.rig.profiles import load_profile

    out = tmp_path / "doe"
    code = main(["doe", "--model", "two-mass", "--duration", "8", "--population", "6",
                 "--generations", "2", "--out", str(out), "--json", str(tmp_path / "s.json")])
    assert code == 0
    load_profile(out / "designed.json")
    for name in ("predicted_covariance.csv", "doe_summary.json", "doe_inputs.png", "doe_std.png"):
        assert (out / name).is_file()
