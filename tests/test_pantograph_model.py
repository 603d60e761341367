"""Physics of the pantograph model on the Python path: kinematics, equilibrium, energy, Jacobians."""
import numpy as np
import pytest
import sympy as sp

from panto.fmu_src.models import Model, default_parameters, numeric_model
from panto.fmu_src.pantograph import linkage
from panto.fmu_src.simulation import SolverOptions, simulate_model

PARAMS = default_parameters("Pantograph")


def _kinematics():
    kin = linkage()
    numeric = numeric_model("Pantograph")
    syms = numeric.model.p + [kin["phi1"], kin["delta"], kin["phi2"], kin["phi3"]]
    fun = {name: sp.lambdify(syms, kin[name]) for name in ("S2", "D2", "S3", "D3", "y_cb", "x_cb")}

    def angles(phi1, delta):
        phi2, phi3 = numeric.dependents(PARAMS.vector(), [phi1, delta, 0.0])
        return phi2, phi3

    def evaluate(name, phi1, delta):
        return fun[name](*PARAMS.vector(), phi1, delta, *angles(phi1, delta))

    return angles, evaluate


WORKING_RANGE = [(phi1, delta) for phi1 in np.radians([1, 10, 20, 30.5, 40, 50])
                 for delta in (-0.01, 0.0, 0.01)]


@pytest.mark.parametrize("phi1,delta", WORKING_RANGE, ids=lambda v: f"{v:.3f}")
def test_linkage_closes_to_machine_precision(phi1, delta):
    angles, _ = _kinematics()
    phi2, phi3 = angles(phi1, delta)
    l1, l2, l3, c, d = (PARAMS[n] for n in ("l1", "l2", "l3", "c", "d"))
    # thesis eqs. (2.1) and (2.2) with l3 -> l3 + delta
    horizontal = l1 * np.cos(phi1) + l2 * np.cos(phi2) - c - (l3 + delta) * np.cos(phi3)
    vertical = l2 * np.sin(phi2) + (l3 + delta) * np.sin(phi3) - d - l1 * np.sin(phi1)
    assert abs(horizontal) < 1e-14 and abs(vertical) < 1e-14


@pytest.mark.parametrize("phi1,delta", WORKING_RANGE, ids=lambda v: f"{v:.3f}")
def test_velocity_coefficients_are_the_partial_derivatives(phi1, delta):
    """S2, D2, S3, D3 (eqs. 2.17-2.18) against central differences of the closed-form angles."""
    angles, evaluate = _kinematics()
    h = 1e-6

    def diff(index, d_phi1, d_delta):
        plus = angles(phi1 + d_phi1, delta + d_delta)[index]
        minus = angles(phi1 - d_phi1, delta - d_delta)[index]
        return np.angle(np.exp(1j * (plus - minus))) / (2 * h)  # immune to 2 pi wraps

    assert evaluate("S2", phi1, delta) == pytest.approx(diff(0, h, 0), rel=1e-6)
    assert evaluate("D2", phi1, delta) == pytest.approx(diff(0, 0, h), rel=1e-6)
    assert evaluate("S3", phi1, delta) == pytest.approx(diff(1, h, 0), rel=1e-6)
    assert evaluate("D3", phi1, delta) == pytest.approx(diff(1, 0, h), rel=1e-6)


def test_cross_bar_rises_almost_vertically_on_the_working_branch():
    """Reference page: y_cb about 0.55 m at phi1 = 0 and 2.7 m at 45 deg, x_cb moves ~0.27 m."""
    _, evaluate = _kinematics()
    assert evaluate("y_cb", 0.0, 0.0) == pytest.approx(0.55, abs=0.01)
    assert evaluate("y_cb", np.radians(45), 0.0) == pytest.approx(2.7, abs=0.02)
    assert abs(evaluate("x_cb", 0.0, 0.0) - evaluate("x_cb", np.radians(45), 0.0)) == pytest.approx(0.27, abs=0.01)


def test_check_point_of_the_reference_page():
    """eta = 2 m, p = 4 bar: phi1 = 30.5 deg, F_c = 81 N, lowest mode about 3.0 Hz."""
    model = Model("Pantograph")
    x0 = model.equilibrium(eta=2.0, p=4.0)
    assert np.degrees(x0[0]) == pytest.approx(30.5, abs=0.05)
    assert model.outputs(x0, 2.0, 4.0)[2] == pytest.approx(81.0, abs=0.5)
    assert np.allclose(model.derivatives(x0, 2.0, 4.0), 0.0, atol=1e-9)
    lowest = model.linearise(2.0, 4.0).natural_frequencies_hz[0]
    assert lowest == pytest.approx(3.0, abs=0.1)


def test_wire_pulls_the_head_below_about_3_2_bar():
    model = Model("Pantograph")
    force = {p: model.outputs(model.equilibrium(2.0, p), 2.0, p)[2] for p in (3.1, 3.3)}
    assert force[3.1] < 0 < force[3.3]


def test_equilibrium_force_grows_with_pressure_by_the_lever_law():
    """dF_c/dp * (dy_cb/dphi1) = k_p at equilibrium (virtual work, stiff contact)."""
    model = Model("Pantograph", {"k_ph": 1e7})
    forces = [model.outputs(model.equilibrium(2.0, p), 2.0, p)[2] for p in (4.0, 4.01)]
    _, evaluate = _kinematics()
    phi1 = model.equilibrium(2.0, 4.0)[0]
    lever = evaluate("y_cb", phi1 + 1e-6, 0.0) - evaluate("y_cb", phi1 - 1e-6, 0.0)
    assert (forces[1] - forces[0]) / 0.01 * lever / 2e-6 == pytest.approx(PARAMS["k_p"], rel=2e-3)


def test_exact_jacobians_match_finite_differences_away_from_equilibrium():
    model = Model("Pantograph")
    numeric, p = model.numeric, model.parameters.vector()
    x = model.equilibrium(2.0, 4.0) + np.array([0.02, 1e-4, 0.01, 0.3, -0.01, 0.2])
    u = np.array([1.98, 4.2])
    A, B, C, D = numeric.jacobians(p, x, u)
    h = 1e-7
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = h * max(1.0, abs(x[j]))
        fd = (numeric.derivatives(p, x + dx, u) - numeric.derivatives(p, x - dx, u)) / (2 * dx[j])
        np.testing.assert_allclose(A[:, j], fd, rtol=1e-5, atol=1e-4 * np.max(np.abs(A)))
        fd = (numeric.outputs(p, x + dx, u) - numeric.outputs(p, x - dx, u)) / (2 * dx[j])
        np.testing.assert_allclose(C[:, j], fd, rtol=1e-6, atol=1e-6)
    for j in range(2):
        du = np.zeros(2)
        du[j] = 1e-6
        fd = (numeric.derivatives(p, x, u + du) - numeric.derivatives(p, x, u - du)) / 2e-6
        np.testing.assert_allclose(B[:, j], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(B)))


@pytest.mark.parametrize("extension", [
    {},
    {"kappa_p": 0.8, "k_c3": 4e7},  # angle-dependent bellow torque and stiffening head suspension
], ids=["thesis model", "with conservative extensions"])
def test_energy_is_conserved_without_damping(extension):
    undamped = {"c1": 0.0, "c2": 0.0, "c3": 0.0, "c_c": 0.0, **extension}
    model = Model("Pantograph", undamped)
    x0 = model.equilibrium(2.0, 4.0) + np.array([0.01, 0.0, 0.005, 0.0, 0.0, 0.1])
    time = np.linspace(0.0, 1.2, 13)
    response = simulate_model(model, time, {"eta": 2.0, "p": 4.0}, initial_state=x0,
                              solver=SolverOptions(method="DOP853", rtol=1e-11, atol=1e-13))
    states = np.column_stack([response[name] for name in model.state_names])
    energy = np.array([model.energy(x, 2.0, 4.0) for x in states])
    kinetic_scale = 0.5 * 6.0 * 0.1**2  # energy given to the system, order of magnitude
    assert np.ptp(states[:, 0]) > 1e-3  # it really moves
    assert np.max(np.abs(energy - energy[0])) < 1e-5 * kinetic_scale


def test_with_damping_it_decays_to_the_equilibrium():
    model = Model("Pantograph")
    x_eq = model.equilibrium(2.0, 4.0)
    x0 = x_eq + np.array([0.01, 0.0, 0.005, 0.0, 0.0, 0.1])
    response = simulate_model(model, np.linspace(0.0, 5.0, 6), {"eta": 2.0, "p": 4.0},
                              initial_state=x0,
                              solver=SolverOptions(method="RK45", rtol=1e-9, atol=1e-12))
    final = np.array([response[name][-1] for name in model.state_names])
    energy = [model.energy(x, 2.0, 4.0) for x in (x0, final)]
    assert np.allclose(final, x_eq, atol=1e-6)
    assert energy[1] < energy[0]


def test_hinge_friction_dissipates_exactly_its_work():
    """E(t1) - E(0) = -integral of T_f tanh(dphi1 / omega_eps) dphi1 dt (only friction dissipates)."""
    t_f, omega_eps = 15.0, 0.05
    model = Model("Pantograph", {"c1": 0.0, "c2": 0.0, "c3": 0.0, "c_c": 0.0,
                                 "T_f": t_f, "omega_eps": omega_eps})
    x0 = model.equilibrium(2.0, 4.0) + np.array([0.0, 0.0, 0.0, 0.3, 0.0, 0.0])  # kick dphi1
    time = np.linspace(0.0, 1.0, 2001)
    response = simulate_model(model, time, {"eta": 2.0, "p": 4.0}, initial_state=x0,
                              solver=SolverOptions(method="DOP853", rtol=1e-11, atol=1e-13))
    states = np.column_stack([response[name] for name in model.state_names])
    energy = np.array([model.energy(x, 2.0, 4.0) for x in states])
    dphi1 = response["dphi1"]
    power = t_f * np.tanh(dphi1 / omega_eps) * dphi1
    dissipated = np.concatenate([[0.0], np.cumsum((power[1:] + power[:-1]) / 2 * np.diff(time))])
    assert dissipated[-1] > 0.05 * (energy[0] - energy.min() + dissipated[-1])  # friction matters
    np.testing.assert_allclose(energy - energy[0], -dissipated, atol=2e-3 * dissipated[-1])


def test_angle_dependent_bellow_torque_equals_a_scaled_pressure():
    """With kappa_p the equilibrium is that of the thesis model at p (1 + kappa_p (phi1 - phi1_ref))."""
    kappa, phi1_ref = 0.6, 0.45
    extended = Model("Pantograph", {"kappa_p": kappa, "phi1_ref": phi1_ref})
    x_ext = extended.equilibrium(2.0, 4.0)
    scaled_pressure = 4.0 * (1 + kappa * (x_ext[0] - phi1_ref))
    x_nominal = Model("Pantograph").equilibrium(2.0, scaled_pressure)
    np.testing.assert_allclose(x_ext, x_nominal, atol=1e-9)
    assert abs(scaled_pressure - 4.0) > 0.1  # the extension really changed the torque


def test_unilateral_contact_releases_the_wire():
    model = Model("Pantograph", {"unilateral_contact": 1.0})
    x = model.equilibrium(2.0, 4.0)
    assert model.outputs(x, 2.0, 4.0)[2] > 0
    lifted_wire = 2.2  # wire above the head: no force, the head is free
    assert model.outputs(x, lifted_wire, 4.0)[2] == 0.0
    bilateral = Model("Pantograph")
    assert bilateral.outputs(x, lifted_wire, 4.0)[2] < 0


def test_unreachable_height_is_refused_with_the_reachable_range():
    with pytest.raises(ValueError, match="reachable"):
        Model("Pantograph").equilibrium(eta=6.0, p=4.0)
