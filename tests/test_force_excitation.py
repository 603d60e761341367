"""Force excitation (thesis Fig. 2.6, sections 2.3, 4.4 and 4.8): the models with the contact force
as an input instead of the contact spring, their unstable or grounded rigid-body mode, and their
FMUs.

The pantograph: bellow torque M_b on the lower arm and contact force F_c on the head. Section 4.4
found it unstable about its equilibrium (a constant torque raises or lowers it without bound). The
check here is the inertia theorem (Kelvin-Tait-Chetaev): with a positive definite mass matrix and
damping, the linearised model has as many eigenvalues in the right half-plane as the static
stiffness matrix K = -dr/dq has negative eigenvalues. Nothing but the weight's lever holds the
linkage, and the torque that holds it falls as it rises: K has one negative eigenvalue, A one small
positive real one. The displacement-excited model (contact spring to eta) is stable.

The oscillators: for the force-input chain the spring k1 to the base is what grounds it. With k1 > 0
a constant force settles at the static deflection (x_1 - y_0 = (F_0 - F_c) / k1, each spring above
shortened by F_c / k_j); with k1 = 0 a zero eigenvalue, and a constant net force drives the chain
at the terminal speed (F_0 - F_c) / c1.
"""
from __future__ import annotations

import numpy as np
import pytest
from fmpy import read_model_description
from scipy import linalg

from panto.build_fmu.crosscheck import check_fmu_with_toolbox
from panto.build_fmu.simulate import FmuSimulator
from panto.fmu_src.models import FORCE_FMU_NAMES, Model
from panto.fmu_src.simulation import simulate_model

FILES = [f"{name}{suffix}.fmu" for name in FORCE_FMU_NAMES for suffix in ("", "_fmi3")]


@pytest.fixture(scope="module")
def operating_point():
    """The displacement model at eta = 2 m, p = 4 bar: its equilibrium, the contact force it
    presses with and the bellow torque k_p p it is lifted by."""
    pantograph = Model("Pantograph")
    x0 = pantograph.equilibrium(2.0, 4.0)
    force = float(pantograph.outputs(x0, 2.0, 4.0)[2])
    return {"model": pantograph, "x0": x0, "F_c": force, "M_b": pantograph.parameters["k_p"] * 4.0}


@pytest.fixture(scope="module")
def force_pantograph():
    """The force-excited pantograph with its default parameters (Table 4.1)."""
    return Model("PantographForce")


def _stiffness(model: Model, linearised) -> np.ndarray:
    """K = -dr/dq at rest, from A's acceleration-position block (A_vq = M^-1 dr/dq at rest)."""
    n = len(linearised.x0) // 2
    mass = model.numeric.mass_matrix(model.parameters.vector(), linearised.x0[:n])
    return -mass @ linearised.A[n:, :n]


def test_force_model_holds_the_displacement_model_equilibrium(operating_point, force_pantograph):
    """Same statics, two paths: the force model fed the displacement model's contact force and
    torque rests where the displacement model does."""
    x_force = force_pantograph.equilibrium(operating_point["M_b"], operating_point["F_c"])
    np.testing.assert_allclose(x_force, operating_point["x0"], rtol=0, atol=1e-9)


def test_force_excited_pantograph_has_one_slow_unstable_mode(operating_point, force_pantograph):
    linearised = force_pantograph.linearise(operating_point["M_b"], operating_point["F_c"])
    stiffness = _stiffness(force_pantograph, linearised)
    np.testing.assert_allclose(stiffness, stiffness.T, atol=1e-9 * np.abs(stiffness).max())
    eigenvalues = linearised.eigenvalues
    unstable = eigenvalues[eigenvalues.real > 0]
    assert np.sum(np.linalg.eigvalsh(stiffness) < 0) == 1 == unstable.size  # inertia theorem
    assert abs(unstable[0].imag) == 0.0  # a real mode: a monotonic rise or fall
    others = eigenvalues[eigenvalues.real <= 0]
    assert unstable[0].real < 0.1 * np.min(np.abs(others))  # nearly the rigid-body zero


def test_displacement_excited_pantograph_is_stable(operating_point):
    pantograph = operating_point["model"]
    linearised = pantograph.linearise(2.0, 4.0)
    assert np.all(linearised.eigenvalues.real < 0)
    assert np.all(np.linalg.eigvalsh(_stiffness(pantograph, linearised)) > 0)


def _linear_step(linearised, input_index: int, step: float, time: np.ndarray, output: int):
    """Output deviation of dx/dt = A x + B du after a step du (exact, by the matrix exponential)."""
    n, m = linearised.A.shape[0], linearised.B.shape[1]
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n], augmented[:n, n:] = linearised.A, linearised.B
    du = np.zeros(m)
    du[input_index] = step
    states = [(linalg.expm(augmented * t)[:n, n:] @ du) for t in time]
    return np.array([linearised.C[output] @ x + linearised.D[output] @ du for x in states])


@pytest.mark.parametrize("step", [0.5, -0.5])
def test_a_constant_torque_raises_or_lowers_it_without_bound(force_fmus, operating_point,
                                                             force_pantograph, step):
    """A torque 0.5 N m above (below) the balance: the FMU's head rises (falls) along the
    linearised model's growing exponential."""
    torque, force = operating_point["M_b"], operating_point["F_c"]
    linearised = force_pantograph.linearise(torque, force)
    t = np.linspace(0.0, 6.0, 601)
    with FmuSimulator(force_fmus["PantographForce.fmu"].path, interface="CS") as simulator:
        rest = simulator.simulate(t, {"M_b": torque, "F_c": force})
        pushed = simulator.simulate(t, {"M_b": torque + step * (t > 0), "F_c": force})
    deviation = pushed["xi"] - rest["xi"]
    expected = _linear_step(linearised, 0, step, t[[200, 400, 600]], output=1)
    np.testing.assert_allclose(deviation[[200, 400, 600]], expected, rtol=0.05)
    assert np.sign(deviation[600]) == np.sign(step)
    assert abs(deviation[600]) > 3 * abs(deviation[300])  # faster than any settling or ramp


@pytest.mark.parametrize("file", FILES)
def test_force_fmus_validate(force_fmus, file):
    assert force_fmus[file].problems == ()
    assert check_fmu_with_toolbox(force_fmus[file].path) == []


@pytest.mark.parametrize("file", ["PantographForce.fmu", "TwoMassForce_fmi3.fmu"])
def test_head_motion_has_no_feedthrough_from_the_force(force_fmus, file):
    """Heights and velocities are states only: a master coupling by force has no algebraic loop."""
    md = read_model_description(str(force_fmus[file].path))
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    assert inputs == ({"M_b", "F_c"} if file.startswith("Pantograph") else {"F_c", "p"})
    for output in md.outputs:
        assert not {v.name for v in output.dependencies} & inputs, output.variable.name


def _force_inputs(name: str, t: np.ndarray) -> dict:
    """A 20 N rise of the contact force (half a cosine, 0.1 s to 0.2 s) and a small ramp of the
    second input."""
    rise = 0.5 - 0.5 * np.cos(np.pi * np.clip((t - 0.1) / 0.1, 0.0, 1.0))
    if name.startswith("Pantograph"):
        return {"M_b": 1040.0 + 2.0 * t, "F_c": 80.0 + 20.0 * rise}
    return {"F_c": 120.0 + 20.0 * rise, "p": 0.0 * t}


@pytest.mark.parametrize("name", ["PantographForce", "TwoMassForce", "ThreeMassForce"])
def test_force_fmu_agrees_with_the_python_model(force_fmus, name):
    """ME on the Python grid (exact piecewise-linear inputs); CS, which holds each step's mean
    input, on a ten times finer grid carrying the same piecewise-linear inputs."""
    t = np.linspace(0.0, 0.6, 61)
    inputs = _force_inputs(name, t)
    python = simulate_model(Model(name), t, inputs)
    fine = np.linspace(0.0, 0.6, 601)
    grids = {"ME": (t, inputs, slice(None)),
             "CS": (fine, {k: np.interp(fine, t, v) for k, v in inputs.items()}, slice(None, None, 10))}
    for file in (f"{name}.fmu", f"{name}_fmi3.fmu"):
        for interface, (grid, signals, common) in grids.items():
            with FmuSimulator(force_fmus[file].path, interface=interface) as simulator:
                fmu = simulator.simulate(grid, signals)
            for output in ("y_cb", "xi", "v_head"):
                scale = np.ptp(python[output])
                assert scale > 1e-3  # the force really moves it
                np.testing.assert_allclose(fmu[output][common], python[output], atol=2e-3 * scale,
                                           err_msg=f"{file} {interface} {output}")


def test_linearised_force_fmu_follows_the_nonlinear_one_for_a_small_force(force_fmus):
    t = np.linspace(0.0, 2.0, 201)
    inputs = {"M_b": 1040.0, "F_c": 80.0 + 2.0 * np.sin(2 * np.pi * 1.5 * t)}
    runs = {}
    for name in ("PantographForce", "PantographForceLinear"):
        with FmuSimulator(force_fmus[f"{name}.fmu"].path, interface="CS") as simulator:
            runs[name] = simulator.simulate(t, inputs, parameters={"M_b0": 1040.0, "F_c0": 80.0}
                                            if name.endswith("Linear") else None)
    nonlinear, linear = runs["PantographForce"]["xi"], runs["PantographForceLinear"]["xi"]
    assert np.ptp(nonlinear) > 1e-4
    assert np.max(np.abs(nonlinear - linear)) < 0.01 * np.ptp(nonlinear)


@pytest.mark.parametrize("name, springs", [("TwoMassForce", (50.0, 4200.0)),
                                           ("ThreeMassForce", (160.0, 15500.0, 7000.0))])
def test_grounded_oscillator_settles_at_its_static_deflection(force_fmus, name, springs):
    """k1 > 0: from rest at F_c = F_0 = 120 N (k1 relaxed) to F_c = 150 N."""
    t = np.linspace(0.0, 40.0, 401)
    with FmuSimulator(force_fmus[f"{name}.fmu"].path, interface="CS") as simulator:
        run = simulator.simulate(t, {"F_c": 120.0 + 30.0 * (t > 0), "p": 0.0})
    assert Model(name).parameters["k1"] == springs[0]

    def head(force: float) -> float:
        return (120.0 - force) / springs[0] - force * sum(1.0 / k for k in springs[1:])

    assert run["xi"][0] == pytest.approx(head(120.0), rel=1e-9)
    assert run["xi"][-1] == pytest.approx(head(150.0), rel=1e-4)
    assert abs(run["v_head"][-1]) < 1e-5


@pytest.mark.parametrize("name, c1", [("TwoMassForce", 90.0), ("ThreeMassForce", 100.0)])
def test_ungrounded_oscillator_drifts_at_its_terminal_speed(force_fmus, name, c1):
    """k1 = 0: a zero eigenvalue, and a net 30 N up drives the chain at 30 N / c1 for ever."""
    model = Model(name, {"k1": 0.0})
    n = len(model.state_names) // 2
    A = model.numeric.jacobians(model.parameters.vector(), np.zeros(2 * n), (120.0, 0.0))[0]
    eigenvalues = np.linalg.eigvals(A)
    assert np.min(np.abs(eigenvalues)) < 1e-12 * np.max(np.abs(eigenvalues))
    assert np.all(eigenvalues.real <= 1e-12 * np.max(np.abs(eigenvalues)))
    t = np.linspace(0.0, 6.0, 61)
    with FmuSimulator(force_fmus[f"{name}.fmu"].path, interface="CS") as simulator:
        run = simulator.simulate(t, {"F_c": 90.0, "p": 0.0},
                                 parameters={"k1": 0.0, "c1": c1, "start_in_equilibrium": False})
    speed = 30.0 / c1
    assert run["v_head"][-1] == pytest.approx(speed, rel=1e-4)
    assert run["v_cb"][-1] == pytest.approx(speed, rel=1e-4)
    assert run["xi"][-1] - run["xi"][-11] == pytest.approx(speed * 1.0, rel=1e-3)
