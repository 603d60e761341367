"""FmuStepper (panto.build_fmu.stepping): CS and ME agree and match FmuSimulator; state, errors."""
import pickle

import numpy as np
import pytest

from panto.build_fmu.simulate import FmuSimulator, SimulationError
from panto.build_fmu.stepping import FmuStepper

STEP = 1e-3
TIME = STEP * np.arange(401)
ETA = 0.01 * np.sin(2 * np.pi * 3.0 * TIME)   # a wire moving by +-10 mm at 3 Hz
MEANS = 0.5 * (ETA[1:] + ETA[:-1])            # the step means FmuSimulator gives a CS FMU


def _stepped(path, interface, **options):
    with FmuStepper(path, step_size=STEP, inputs=["eta"], outputs=["y_cb", "xi"],
                    interface=interface, **options) as stepper:
        rows = [stepper.initialise({"eta": ETA[0]})]
        rows += [stepper.step([value]) for value in MEANS]
        assert stepper.time == pytest.approx(TIME[-1])
        assert stepper.calls == len(MEANS)
    return np.array(rows)


@pytest.mark.parametrize("fmu", ["TwoMass.fmu", "TwoMass_fmi3.fmu"], ids=["fmi2", "fmi3"])
def test_cs_and_me_stepping_agree_and_match_the_simulator(project_fmus, fmu):
    path = project_fmus[fmu].path
    with FmuSimulator(path, interface="CS", output_names=["y_cb", "xi"]) as simulator:
        whole_cs = simulator.simulate(TIME, {"eta": ETA})
    with FmuSimulator(path, interface="ME", output_names=["y_cb", "xi"]) as simulator:
        whole_me = simulator.simulate(TIME, {"eta": ETA}, solver_tolerance=1e-10)
    cs = _stepped(path, "CS")
    me = _stepped(path, "ME", solver_tolerance=1e-10)
    scale = np.ptp(whole_cs["xi"])
    assert scale > 0.01  # the head really moves with the wire
    # same doStep calls with the same (step-mean) inputs: identical to round-off
    np.testing.assert_allclose(cs[:, 1], whole_cs["xi"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(cs[:, 0], whole_cs["y_cb"], rtol=0, atol=1e-12)
    # CVODE between communication points with the same held inputs: same trajectory
    np.testing.assert_allclose(me, cs, rtol=0, atol=1e-6 * scale)
    # piecewise-linear instead of held inputs: an O(h^2) difference only
    np.testing.assert_allclose(me[:, 1], whole_me["xi"], rtol=0, atol=1e-3 * scale)


def test_state_save_and_restore(project_fmus):
    path = project_fmus["TwoMass.fmu"].path
    with FmuStepper(path, step_size=STEP, inputs=["eta"], outputs=["xi", "F_c"],
                    parameters={"unilateral_contact": True}) as stepper:
        assert stepper.can_get_and_set_state
        stepper.initialise([0.0])
        for value in MEANS[:50]:
            stepper.step([value])
        saved = stepper.get_state()
        first = np.array([stepper.step([value]) for value in MEANS[50:80]])
        stepper.set_state(saved)
        assert stepper.time == pytest.approx(50 * STEP)
        again = np.array([stepper.step([value]) for value in MEANS[50:80]])
        stepper.free_state(saved)
        with pytest.raises(ValueError, match="does not belong"):
            stepper.set_state(saved)
    np.testing.assert_array_equal(first, again)
    assert not np.allclose(first[0], first[-1])  # the restored run was not a trivial one


def test_unknown_names_list_the_valid_ones(project_fmus):
    path = project_fmus["TwoMass.fmu"].path
    with pytest.raises(ValueError, match=r"no input named 'height'.*valid input names: eta, p"):
        FmuStepper(path, step_size=STEP, inputs=["height"], outputs=["F_c"])
    with pytest.raises(ValueError, match="valid Real/Float64 variable names"):
        FmuStepper(path, step_size=STEP, inputs=["eta"], outputs=["force"])
    with pytest.raises(ValueError, match="no variable named 'mass'"):
        FmuStepper(path, step_size=STEP, inputs=["eta"], outputs=["F_c"],
                   parameters={"mass": 1.0})
    with pytest.raises(ValueError, match="step_size"):
        FmuStepper(path, step_size=0.0, inputs=["eta"], outputs=["F_c"])


def test_failed_call_raises_with_function_status_and_log(project_fmus):
    path = project_fmus["TwoMass.fmu"].path
    with FmuStepper(path, step_size=STEP, inputs=["eta"], outputs=["F_c"],
                    parameters={"m1": -1.0}) as stepper:
        with pytest.raises(SimulationError) as caught:
            stepper.initialise([0.0])
    error = caught.value
    assert error.function == "fmi2SetReal" and error.status == 3
    assert any("m1" in line and "admissible" in line for line in error.messages)


def test_step_before_initialise_and_wrong_input_count(project_fmus):
    with FmuStepper(project_fmus["TwoMass.fmu"].path, step_size=STEP, inputs=["eta", "p"],
                    outputs=["F_c"]) as stepper:
        with pytest.raises(RuntimeError, match="initialise"):
            stepper.step([0.0, 0.0])
        with pytest.raises(ValueError, match="expected 2 input"):
            stepper.initialise([0.0])


def test_pickles_as_a_fresh_stepper(project_fmus):
    with FmuStepper(project_fmus["TwoMass.fmu"].path, step_size=STEP, inputs=["eta"],
                    outputs=["xi"], parameters={"F_0": 100.0}) as stepper:
        copy = pickle.loads(pickle.dumps(stepper))
    with copy:
        assert copy.step_size == STEP and copy.parameters == {"F_0": 100.0}
        assert np.isfinite(copy.initialise([0.0])[0])
