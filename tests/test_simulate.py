"""Simulating FMUs with :mod:`panto.build_fmu.simulate`: physics, agreement, reuse, errors.

The toy FMUs of ``tests/fixtures/toy_model.py`` (a mass on a spring and damper, pushed by
``gain * p`` and touching the contact line ``eta`` through the contact spring ``k_E``) are built
once per session with FMI 2.0 and 3.0. The reference is the exact solution of the same linear ODE
for piecewise-linear inputs (``scipy.signal.lsim``, matrix exponential), written from the
fixture's closed-form matrices, from the static equilibrium at the first input sample.
"""
from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from panto.build_fmu import build_fmu
from panto.build_fmu.simulate import (FmuSimulator, PiecewiseLinearInputs, SimulationError,
                                UnknownVariableError, simulate_fmu_with_inputs)
from fixtures.toy_model import (ToyParameters, analytic_equilibrium, analytic_matrices,
                                      make_toy_spec)

INTERFACES = ["ME", "CS"]
FMI_VERSIONS = [2, 3]
TIME = np.linspace(0.0, 1.0, 1001)
TIGHT = 1e-9  # solver tolerance for comparisons with the exact solution
DEFAULTS = ToyParameters()


@pytest.fixture(scope="session")
def toy_fmus(tmp_path_factory) -> dict[int, Path]:
    """FMI version → the toy FMU (Model Exchange and Co-Simulation in each)."""
    directory = tmp_path_factory.mktemp("simulate_toy")
    return {version: build_fmu(make_toy_spec(), directory, fmi_version=version)
            for version in FMI_VERSIONS}


def exact_response(time: np.ndarray, eta: np.ndarray, p_bar: np.ndarray,
                   parameters: ToyParameters = DEFAULTS) -> dict[str, np.ndarray]:
    """x and F_c of the linear toy for inputs linear between samples, from equilibrium."""
    system = signal.StateSpace(*analytic_matrices(parameters))
    z0 = analytic_equilibrium(parameters, eta[0], p_bar[0])
    _, outputs, _ = signal.lsim(system, np.column_stack([eta, p_bar]), time, X0=[z0, 0.0],
                                interp=True)
    return {"x": outputs[:, 0], "F_c": outputs[:, 1]}


def excitation(time: np.ndarray) -> dict[str, np.ndarray]:
    """Contact line moving a few millimetres (sine plus drift) under a pressure ramp 4 → 4.5 bar."""
    eta = 0.01 + 0.004 * np.sin(2 * np.pi * 3.0 * time) + 0.002 * time
    p_bar = 4.0 + 0.5 * np.clip((time - 0.3) / 0.1, 0.0, 1.0)
    return {"eta": eta, "p": p_bar}


def relative_error(actual: np.ndarray, expected: np.ndarray) -> float:
    """Largest deviation relative to the signal's range."""
    return float(np.max(np.abs(actual - expected)) / np.ptp(expected))


# --- agreement with the exact solution and between interfaces -------------------------------

@pytest.mark.parametrize("fmi_version", FMI_VERSIONS, ids=lambda v: f"fmi{v}")
@pytest.mark.parametrize("interface, accuracy", [("ME", 2e-5), ("CS", 1e-3)],
                         ids=["ME", "CS"])
def test_response_matches_the_exact_linear_solution(toy_fmus, fmi_version, interface, accuracy):
    # CS holds each input at its step mean: second order in the 1 ms step, hence looser
    inputs = excitation(TIME)
    with FmuSimulator(toy_fmus[fmi_version], interface=interface) as simulator:
        response = simulator.simulate(TIME, inputs, solver_tolerance=TIGHT)
    exact = exact_response(TIME, inputs["eta"], inputs["p"])
    assert response.names == ("x", "F_c")
    for name in response.names:
        assert relative_error(response[name], exact[name]) < accuracy, name


@pytest.mark.parametrize("fmi_version", FMI_VERSIONS, ids=lambda v: f"fmi{v}")
def test_model_exchange_and_co_simulation_agree(toy_fmus, fmi_version):
    inputs = excitation(TIME)
    results = {interface: simulate_fmu_with_inputs(toy_fmus[fmi_version], TIME, inputs,
                                                   interface=interface, solver_tolerance=TIGHT)
               for interface in INTERFACES}
    for name in ("x", "F_c"):
        assert relative_error(results["CS"][name], results["ME"][name]) < 1e-3, name


@pytest.mark.parametrize("interface", INTERFACES)
def test_fmi2_and_fmi3_give_the_same_response(toy_fmus, interface):
    inputs = excitation(TIME)
    fmi2, fmi3 = (simulate_fmu_with_inputs(toy_fmus[version], TIME, inputs, interface=interface)
                  for version in FMI_VERSIONS)
    assert np.allclose(fmi2["F_c"], fmi3["F_c"], rtol=1e-9, atol=1e-9)
    assert (fmi2.metadata["fmi_version"], fmi3.metadata["fmi_version"]) == ("2.0", "3.0")


@pytest.mark.parametrize("interface", INTERFACES)
def test_response_starts_in_static_equilibrium(toy_fmus, interface):
    inputs = excitation(TIME)
    response = simulate_fmu_with_inputs(toy_fmus[2], TIME, inputs, interface=interface)
    z0 = analytic_equilibrium(DEFAULTS, inputs["eta"][0], inputs["p"][0])
    assert response["x"][0] == pytest.approx(z0, rel=1e-9)
    assert response["F_c"][0] == pytest.approx(DEFAULTS.k_E * (z0 - inputs["eta"][0]), rel=1e-9)


# --- one instance, many runs ----------------------------------------------------------------

@pytest.mark.parametrize("fmi_version", FMI_VERSIONS, ids=lambda v: f"fmi{v}")
@pytest.mark.parametrize("interface", INTERFACES)
def test_reused_instance_repeats_runs_exactly_and_leaks_no_state(toy_fmus, fmi_version,
                                                                 interface):
    inputs = excitation(TIME)
    with FmuSimulator(toy_fmus[fmi_version], interface=interface) as simulator:
        first = simulator.simulate(TIME, inputs)
        repeated = simulator.simulate(TIME, inputs)
        stiffer = simulator.simulate(TIME, inputs, parameters={"k": 2 * DEFAULTS.k, "c": 5.0})
        with pytest.raises(SimulationError):  # fails mid-run: the mass leaves its travel
            simulator.simulate(TIME, inputs, parameters={"x_max": 0.016})
        no_contact = simulator.simulate(TIME, inputs, parameters={"contact_active": False})
        after_other_runs = simulator.simulate(TIME, inputs)
    for name in first.names:
        assert np.array_equal(repeated[name], first[name]), name
        assert np.array_equal(after_other_runs[name], first[name]), name
    assert not np.allclose(stiffer["x"], first["x"])
    assert np.all(no_contact["F_c"] == 0.0)
    assert after_other_runs.metadata["parameters"]["k"] == DEFAULTS.k
    assert after_other_runs.metadata["parameters"]["contact_active"] is True


@pytest.mark.parametrize("interface", INTERFACES)
def test_fresh_and_reused_instances_agree(toy_fmus, interface):
    inputs = excitation(TIME)
    changes = {"k": 1500.0, "c": 35.0}
    with FmuSimulator(toy_fmus[3], interface=interface) as simulator:
        simulator.simulate(TIME, inputs)
        reused = simulator.simulate(TIME, inputs, parameters=changes)
    fresh = simulate_fmu_with_inputs(toy_fmus[3], TIME, inputs, interface=interface,
                                     parameters=changes)
    assert np.array_equal(reused["F_c"], fresh["F_c"])


# --- physics of parameter changes -----------------------------------------------------------

@pytest.mark.parametrize("changes", [{}, {"gain": 20.0}, {"k": 2000.0}, {"k_E": 20000.0},
                                     {"contact_active": False}],
                         ids=["defaults", "double-gain", "double-k", "stiffer-contact",
                              "no-contact"])
@pytest.mark.parametrize("interface", INTERFACES)
def test_static_contact_force_follows_the_static_balance(toy_fmus, interface, changes):
    # at rest (k + k_E) z = gain p + k_E eta, so F_c = k_E (z - eta)
    #                                               = k_E (gain p - k eta) / (k + k_E)
    eta, p_bar = 0.012, 4.5
    parameters = dataclasses.replace(DEFAULTS, **changes)
    k_e = parameters.contact_stiffness
    expected = k_e * (parameters.gain * p_bar - parameters.k * eta) / (parameters.k + k_e)
    response = simulate_fmu_with_inputs(toy_fmus[3], TIME, {"eta": eta, "p": p_bar},
                                        interface=interface, parameters=changes)
    assert np.allclose(response["F_c"], expected, rtol=1e-7, atol=1e-9)


def test_contact_force_steps_by_the_static_gain_when_the_pressure_steps(toy_fmus):
    # a pressure step dp changes the settled contact force by k_E gain dp / (k + k_E)
    time = np.linspace(0.0, 2.0, 2001)
    p_bar = np.where(time < 0.05, 4.0, 5.0)
    response = simulate_fmu_with_inputs(toy_fmus[2], time, {"eta": 0.01, "p": p_bar},
                                        interface="ME", solver_tolerance=TIGHT)
    step = DEFAULTS.k_E * DEFAULTS.gain * 1.0 / (DEFAULTS.k + DEFAULTS.k_E)
    assert response["F_c"][-1] - response["F_c"][0] == pytest.approx(step, rel=1e-4)


# --- options ----------------------------------------------------------------------------------

def test_output_interval_samples_the_same_trajectory(toy_fmus):
    inputs = excitation(TIME)
    with FmuSimulator(toy_fmus[2], interface="ME") as simulator:
        fine = simulator.simulate(TIME, inputs, solver_tolerance=TIGHT)
        coarse = simulator.simulate(TIME, inputs, output_interval=0.01, solver_tolerance=TIGHT)
    assert np.allclose(coarse.time, np.linspace(0.0, 1.0, 101), rtol=0, atol=1e-12)
    assert relative_error(coarse["F_c"], fine.resample(coarse.time)["F_c"]) < 1e-5


def test_response_carries_units_and_metadata(toy_fmus):
    with FmuSimulator(toy_fmus[3], interface="CS", output_names=["F_c", "x", "p"]) as simulator:
        response = simulator.simulate(TIME, {"p": 5.0}, parameters={"c": 60})
    assert response.names == ("F_c", "x", "p")
    assert dict(response.units) == {"F_c": "N", "x": "m", "p": "bar"}
    assert np.all(response["p"] == 5.0)
    metadata = response.metadata
    assert (metadata["model"], metadata["interface"], metadata["fmi_version"]) == \
        ("Toy", "CS", "3.0")
    assert metadata["parameters"]["c"] == 60.0 and metadata["parameters"]["k"] == DEFAULTS.k
    assert metadata["input_interpolation"] == "linear"


def test_missing_inputs_are_held_at_their_start_values(toy_fmus):
    with FmuSimulator(toy_fmus[2]) as simulator:
        implicit = simulator.simulate(TIME)
        explicit = simulator.simulate(TIME, {"eta": 0.01, "p": 4.0})  # the spec's start values
    assert np.array_equal(implicit["F_c"], explicit["F_c"])
    assert implicit["F_c"] == pytest.approx(np.full(TIME.size, 25.0))


def test_extracted_folder_is_accepted_and_kept(toy_fmus, tmp_path):
    from fmpy import extract

    folder = Path(extract(str(toy_fmus[2]), tmp_path / "toy"))
    with FmuSimulator(folder) as simulator:
        response = simulator.simulate(TIME)
    assert (folder / "modelDescription.xml").is_file()
    assert response["F_c"][-1] == pytest.approx(25.0)


def test_pickled_simulator_reopens_the_same_fmu(toy_fmus):
    # what a process-pool executor does with a simulator passed to its workers
    inputs = excitation(TIME)
    with FmuSimulator(toy_fmus[3], interface="ME", output_names=["F_c"]) as simulator:
        original = simulator.simulate(TIME, inputs)
        with pickle.loads(pickle.dumps(simulator)) as copy:
            assert (copy.interface, copy.output_names) == ("ME", ("F_c",))
            assert np.array_equal(copy.simulate(TIME, inputs)["F_c"], original["F_c"])


def test_closed_simulator_refuses_to_run(toy_fmus):
    simulator = FmuSimulator(toy_fmus[2])
    simulator.close()
    simulator.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        simulator.simulate(TIME)


def test_step_means_of_piecewise_linear_inputs_are_exact():
    # u = 2 t on [0, 1], 3 - t on [1, 3]
    inputs = PiecewiseLinearInputs(np.array([0.0, 1.0, 3.0]), np.array([[0.0], [2.0], [0.0]]))
    points = np.array([0.0, 0.5, 2.0, 3.0])
    assert np.allclose(inputs.means(points)[:, 0], [0.5, (0.75 + 1.5) / 1.5, 0.5])
    assert np.allclose(inputs.sample(points)[:, 0], [0.0, 1.0, 1.0, 0.0])
    assert np.allclose(inputs.at(2.0), [1.0])


# --- errors -------------------------------------------------------------------------------------

@pytest.mark.parametrize("call, match", [
    (lambda s: s.simulate(TIME, {"zeta": 0.0}), r"no input named 'zeta'.*eta, p"),
    (lambda s: s.simulate(TIME, parameters={"mass": 1.0}), r"no parameter named 'mass'.*k_E"),
    (lambda s: s.simulate(TIME, parameters={"eta": 1.0}), r"no parameter named 'eta'"),
    (lambda s: s.simulate(TIME, start_values={"nothing": 1.0}), r"no variable named 'nothing'"),
], ids=["input", "parameter", "input-as-parameter", "start-value"])
def test_unknown_names_list_the_valid_ones(toy_fmus, call, match):
    with FmuSimulator(toy_fmus[2]) as simulator:
        with pytest.raises(UnknownVariableError, match=match):
            call(simulator)


def test_unknown_output_name_lists_the_valid_ones(toy_fmus):
    with pytest.raises(UnknownVariableError, match=r"no Real/Float64 variable named 'F'.*F_c"):
        FmuSimulator(toy_fmus[3], output_names=["F"])


@pytest.mark.parametrize("time, inputs, parameters, match", [
    (TIME, {"eta": np.zeros(3)}, {}, r"input 'eta' has shape \(3,\)"),
    (TIME, {"p": np.full(TIME.size, np.nan)}, {}, r"input 'p' has non-finite samples"),
    (TIME[::-1], {}, {}, r"strictly increasing"),
    (TIME[:1], {}, {}, r"at least 2 points"),
    (TIME, {}, {"k": float("inf")}, r"bad value inf for Real variable 'k'"),
    (TIME, {}, {"contact_active": "yes"}, r"bad value 'yes' for Boolean variable"),
], ids=["input-length", "nan-input", "time-backwards", "one-point", "infinite-parameter",
        "text-boolean"])
def test_bad_requests_are_refused_before_simulating(toy_fmus, time, inputs, parameters, match):
    with FmuSimulator(toy_fmus[2]) as simulator:
        with pytest.raises(ValueError, match=match):
            simulator.simulate(time, inputs, parameters=parameters)


def test_bad_interface_is_refused(toy_fmus):
    with pytest.raises(ValueError, match="interface must be one of"):
        FmuSimulator(toy_fmus[2], interface="SE")


@pytest.mark.parametrize("fmi_version", FMI_VERSIONS, ids=lambda v: f"fmi{v}")
@pytest.mark.parametrize("interface", INTERFACES)
def test_failing_model_raises_with_the_fmu_log_and_time(toy_fmus, fmi_version, interface):
    inputs = excitation(TIME)  # the mass rises above 16 mm after about 35 ms
    with FmuSimulator(toy_fmus[fmi_version], interface=interface) as simulator:
        with pytest.raises(SimulationError, match="left its travel") as caught:
            simulator.simulate(TIME, inputs, parameters={"x_max": 0.016})
    error = caught.value
    assert error.function.startswith(f"fmi{fmi_version}")
    assert error.status == 3
    assert 0.0 < error.time < 0.1
    assert any("exceeds x_max = 0.016 m" in message for message in error.messages)


@pytest.mark.parametrize("fmi_version", FMI_VERSIONS, ids=lambda v: f"fmi{v}")
def test_refused_parameter_value_raises_with_the_fmu_log(toy_fmus, fmi_version):
    with FmuSimulator(toy_fmus[fmi_version]) as simulator:
        with pytest.raises(SimulationError, match=r"'m'.*outside its admissible range") as caught:
            simulator.simulate(TIME, parameters={"m": -1.0})
    assert caught.value.time == 0.0
    assert "FMU log" in str(caught.value)
