"""The project's FMUs: validity, ME against CS, FMU against the Python path, linear against
nonlinear, exact directional derivatives, an independent importer and an FMU checker."""
import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model

from panto.build_fmu.crosscheck import check_fmu_with_toolbox, simulate_in_independent_importer
from panto.build_fmu.simulate import FmuSimulator
from panto.fmu_src.models import DISPLACEMENT_FMU_NAMES, Model
from panto.fmu_src.simulation import simulate_model

FILES = [f"{name}{suffix}.fmu" for name in DISPLACEMENT_FMU_NAMES for suffix in ("", "_fmi3")]


def _step_inputs(name: str, t: np.ndarray) -> dict:
    """A 5 mm step of the wire at 0.1 s and a pressure ramp, about each model's start values."""
    eta0 = 2.0 if name.startswith("Pantograph") else 0.0
    return {"eta": eta0 + 0.005 * (t > 0.1), "p": 4.0 + 0.2 * t} if eta0 else \
           {"eta": eta0 + 0.005 * (t > 0.1), "p": 0.0 * t}


@pytest.mark.parametrize("file", FILES)
def test_fmpy_validator_finds_no_problem(project_fmus, file):
    assert project_fmus[file].problems == ()


@pytest.mark.parametrize("file", FILES)
def test_toolbox_checker_accepts_it(project_fmus, file):
    assert check_fmu_with_toolbox(project_fmus[file].path) == []


@pytest.mark.parametrize("file", FILES)
def test_model_exchange_and_co_simulation_agree(project_fmus, file):
    t = np.linspace(0.0, 1.0, 501)
    inputs = _step_inputs(file, t)
    results = {}
    for interface in ("ME", "CS"):
        with FmuSimulator(project_fmus[file].path, interface=interface) as simulator:
            results[interface] = simulator.simulate(t, inputs)
    force = results["CS"]["F_c"]
    assert np.ptp(force) > 1.0  # the step really excites it
    np.testing.assert_allclose(results["ME"]["F_c"], force, atol=2e-3 * np.ptp(force))
    height = results["CS"]["y_cb"]
    np.testing.assert_allclose(results["ME"]["y_cb"], height, atol=2e-3 * max(np.ptp(height), 1e-6))


@pytest.mark.parametrize("name", ["Pantograph", "TwoMass", "ThreeMass"])
def test_fmu_and_python_path_agree(project_fmus, name):
    t = np.linspace(0.0, 0.6, 61)
    inputs = _step_inputs(name, t)
    with FmuSimulator(project_fmus[f"{name}.fmu"].path, interface="ME") as simulator:
        fmu = simulator.simulate(t, inputs)
    python = simulate_model(Model(name), t, inputs)
    for output in ("y_cb", "xi", "F_c"):
        scale = max(np.ptp(python[output]), 1e-9)
        np.testing.assert_allclose(fmu[output], python[output], atol=2e-3 * scale, err_msg=output)


def _pantograph_pair(project_fmus, amplitude: float):
    t = np.linspace(0.0, 3.0, 1501)
    inputs = {"eta": 2.0 + amplitude * np.sin(2 * np.pi * 1.3 * t), "p": 4.0 + 0.0 * t}
    runs = {}
    for name in ("Pantograph", "PantographLinear"):
        with FmuSimulator(project_fmus[f"{name}.fmu"].path, interface="CS") as simulator:
            runs[name] = simulator.simulate(t, inputs)
    return runs["Pantograph"]["F_c"], runs["PantographLinear"]["F_c"]


def test_linearised_fmu_agrees_for_a_small_excitation(project_fmus):
    nonlinear, linear = _pantograph_pair(project_fmus, amplitude=0.001)
    assert np.max(np.abs(nonlinear - linear)) < 0.01 * np.ptp(nonlinear)


def test_linearised_fmu_departs_for_a_large_excitation(project_fmus):
    nonlinear, linear = _pantograph_pair(project_fmus, amplitude=0.3)
    assert np.max(np.abs(nonlinear - linear)) > 0.05 * np.ptp(nonlinear)


def test_directional_derivatives_equal_the_python_linearisation(project_fmus, tmp_path):
    path = project_fmus["Pantograph.fmu"].path
    md = read_model_description(path)
    refs = {v.name: v.valueReference for v in md.modelVariables}
    model = Model("Pantograph")
    lin = model.linearise(2.0, 4.0)
    states = ["phi1", "delta", "xi_state", "dphi1", "ddelta", "dxi"]
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(path, tmp_path), modelIdentifier="Pantograph",
                    instanceName="jacobian")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    unknown = [refs[f"der({s})"] for s in states]
    for j, known in enumerate(states + ["eta", "p"]):
        column = fmu.getDirectionalDerivative(unknown, [refs[known]], [1.0])
        expected = lin.A[:, j] if j < 6 else lin.B[:, j - 6]
        np.testing.assert_allclose(column, expected, rtol=1e-8, atol=1e-8 * np.max(np.abs(lin.A)))
    fmu.terminate()
    fmu.freeInstance()


@pytest.mark.parametrize("file", ["Pantograph.fmu", "Pantograph_fmi3.fmu", "TwoMass.fmu"])
def test_independent_importer_runs_it_like_fmpy(project_fmus, file):
    """Released from its (non-equilibrium) state start values, it moves the same in both."""
    path = project_fmus[file].path
    eta = 2.003 if file.startswith("Pantograph") else 0.003
    release = {"start_in_equilibrium": False}
    other = simulate_in_independent_importer(path, stop_time=0.5, step_size=0.002, inputs={"eta": eta},
                                             parameters=release, outputs=["F_c"])
    t = np.linspace(0.0, 0.5, 251)
    with FmuSimulator(path, interface="CS") as simulator:
        reference = simulator.simulate(t, {"eta": np.full_like(t, eta)}, parameters=release)
    assert np.ptp(reference["F_c"]) > 1.0
    np.testing.assert_allclose(other["F_c"][1:], reference["F_c"][1:], atol=1e-3 * np.ptp(reference["F_c"]))


def test_en50318_reference_pantograph_static_force(project_fmus):
    """Two-mass defaults = EN 50318 reference pantograph: F_c = (F0 - k1 (eta - y0)) / (1 + k1 (1/kE + 1/k2))."""
    eta = 0.05
    with FmuSimulator(project_fmus["TwoMass_fmi3.fmu"].path, interface="CS") as simulator:
        r = simulator.simulate(np.array([0.0, 0.1]), {"eta": np.array([eta, eta])})
    expected = (120.0 - 50.0 * eta) / (1 + 50.0 * (1 / 50000.0 + 1 / 4200.0))
    assert r["F_c"][-1] == pytest.approx(expected, rel=1e-9)


def test_unreachable_linkage_is_an_fmi_error_not_a_crash(project_fmus):
    with FmuSimulator(project_fmus["Pantograph.fmu"].path, interface="CS") as simulator:
        with pytest.raises(Exception, match="reachable|close"):
            simulator.simulate(np.linspace(0, 0.1, 11), {"eta": np.full(11, 6.0)})
