"""The co-simulation loop in C (panto.catenary_cosim.coupling_kernel) against the Python loop.

Two independent drivers of the same coupling: the Python loop calls the FMU through fmpy's ctypes
functions (FmuStepper.step) and the catenary through Catenary.advance; the C loop calls the FMU's
FMI functions directly and the catenary's C step. Same operations in the same order: the runs
must agree to round-off, slack droppers, contact loss, sub-steps and a second input included.
"""
import dataclasses

import numpy as np
import pytest

from panto.catenary_cosim import coupling_kernel, kernel
from panto.catenary_cosim.catenary import Catenary
from panto.catenary_cosim.lines import load_line
from panto.catenary_cosim.master import cosimulate
from panto.catenary_cosim.pantographs import pantograph_setup


@pytest.fixture(scope="module")
def short_line():
    """The EN 50318 line cut to three spans (analysed: the middle one)."""
    return dataclasses.replace(load_line("en50318-2002"), spans=3, analysed_spans=(2, 2))


@pytest.fixture(autouse=True)
def _compiled_kernel():
    if kernel.load_library() is None or coupling_kernel.load_library() is None:
        pytest.skip("no C compiler: the compiled step and loop are not available")


def _both_loops(line, setup, *, time_step=5e-4, speed_kmh=250.0, **settings):
    """The same run with the C loop and the Python loop, each on a fresh catenary."""
    runs = []
    for compiled in (True, False):
        catenary = Catenary(line, time_step=time_step, element_length=1.0)
        lines = []
        result = cosimulate(catenary, setup, speed_kmh=speed_kmh, compiled_loop=compiled,
                            progress=lines.append, **settings)
        runs.append((result, catenary, lines))
    return runs


@pytest.mark.parametrize("case", ["strong-uplift-substeps", "weak-uplift-contact-loss",
                                  "physical"])
def test_compiled_loop_equals_the_python_loop(project_fmus, short_line, case):
    if case == "physical":  # nonlinear FMU, a second (constant) input, the head mapped by 2 m
        setup = pantograph_setup("physical").with_fmu(project_fmus["Pantograph.fmu"].path)
        settings = {"stop_position": 30.0}
    else:
        strong = case.startswith("strong")
        setup = pantograph_setup("en50318-2002").with_fmu(
            project_fmus["TwoMass.fmu"].path).with_parameters(F_0=400.0 if strong else 40.0)
        settings = ({"communication_step": 1e-3, "stop_position": 70.0} if strong
                    else {"speed_kmh": 300.0, "time_step": 2e-4, "stop_position": 70.0})
    (fast, fast_line, fast_say), (slow, slow_line, slow_say) = _both_loops(short_line, setup,
                                                                           **settings)
    assert (fast.settings["loop"], slow.settings["loop"]) == ("compiled", "python")
    assert np.ptp(fast.contact_force) > 10.0
    np.testing.assert_allclose(fast.contact_force, slow.contact_force, rtol=0, atol=1e-9)
    for name in ("position", "wire_height", "head_height", "support_uplift"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=0, atol=1e-12)
    assert fast.counters == slow.counters
    assert fast_line.time == pytest.approx(slow_line.time, rel=1e-12)
    assert [text.split("x =")[0] for text in fast_say] == [text.split("x =")[0]
                                                           for text in slow_say]
    energy_fast, energy_slow = fast_line.energy(), slow_line.energy()
    for key in ("kinetic", "potential", "dissipated", "work", "dropper_defect"):
        assert energy_fast[key] == pytest.approx(energy_slow[key], rel=1e-9, abs=1e-12)
    if case == "strong-uplift-substeps":  # the droppers went slack and taut again in the run
        assert energy_fast["dropper_defect"] != 0.0
    if case == "weak-uplift-contact-loss":
        assert fast.counters["contact_loss_samples"] > 0


def test_fmi3_and_model_exchange_keep_the_python_loop(project_fmus, short_line):
    """The C loop drives FMI 2.0 Co-Simulation only; the others run the Python loop and give
    the same run as the C loop on the FMI 2.0 FMU."""
    runs = {}
    for name, fmu, interface in (("fmi2", "TwoMass.fmu", "CS"), ("fmi3", "TwoMass_fmi3.fmu", "CS"),
                                 ("me", "TwoMass.fmu", "ME")):
        setup = pantograph_setup("en50318-2002").with_fmu(project_fmus[fmu].path)
        runs[name] = cosimulate(short_line, setup, speed_kmh=250.0, element_length=2.0,
                                stop_position=40.0, interface=interface)
    assert [runs[k].settings["loop"] for k in ("fmi2", "fmi3", "me")] == ["compiled", "python",
                                                                          "python"]
    force = runs["fmi2"].contact_force
    np.testing.assert_allclose(runs["fmi3"].contact_force, force, rtol=0, atol=1e-9)
    np.testing.assert_allclose(runs["me"].contact_force, force, rtol=0, atol=1e-3 * np.ptp(force))


def test_an_fmu_error_inside_the_loop_is_raised_as_by_the_python_loop(project_fmus, short_line):
    """The height input leaves the FMU's admissible range (eta <= 200 m) as the wire rises
    under the head: fmi2SetReal fails mid-run, and both loops raise the same SimulationError
    (function, status, time, FMU log)."""
    from panto.build_fmu.simulate import SimulationError

    offset = 200.0 - 5.3 - 0.005  # eta starts 5 mm below its maximum
    setup = dataclasses.replace(
        pantograph_setup("en50318-2002").with_fmu(project_fmus["TwoMass.fmu"].path),
        height_offset=offset).with_parameters(  # relaxed at 100 m: 120 N static at eta
            y_0=100.0, F_0=120.0 + 50.0 * (5.3 + offset - 100.0))
    errors = []
    for compiled in (True, False):
        with pytest.raises(SimulationError) as caught:
            cosimulate(short_line, setup, speed_kmh=250.0, element_length=2.0,
                       stop_position=40.0, compiled_loop=compiled)
        errors.append(caught.value)
    assert errors[0].time > 0.0 and errors[0].time == errors[1].time
    assert str(errors[0]) == str(errors[1]) and "fmi2SetReal" in str(errors[0])
