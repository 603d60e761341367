"""The catenary as a pythonfmu Co-Simulation FMU, coupled with the TwoMass FMU through fmpy by a
tiny master, matches the in-process master (panto.catenary_cosim.catenary_fmu)."""
import json

import numpy as np
import pytest

from panto.build_fmu.stepping import FmuStepper
from panto.catenary_cosim.catenary_fmu import build_catenary_fmu
from panto.catenary_cosim.lines import LINE_DIRECTORY, load_line
from panto.catenary_cosim.master import cosimulate
from panto.catenary_cosim.pantographs import pantograph_setup

TIME_STEP, SUBSTEPS, SPEED_KMH = 5e-4, 2, 250.0


@pytest.fixture(scope="module")
def short_line_file(tmp_path_factory):
    """The EN 50318 line cut to two spans, as a line file (the FMU reads lines from files)."""
    data = json.loads((LINE_DIRECTORY / "en50318-2002.json").read_text())
    data["name"] = "en50318-two-spans"
    data["items"]["spans"]["value"] = 2
    data["items"]["analysed_spans"]["value"] = [2, 2]
    path = tmp_path_factory.mktemp("lines") / "two_spans.json"
    path.write_text(json.dumps(data))
    return path


def _fmu_master(catenary_fmu, pantograph_fmu, setup, line, stop):
    """Gauss-Seidel, pantograph first, as the in-process master (its module notes)."""
    step = SUBSTEPS * TIME_STEP
    speed = SPEED_KMH / 3.6
    catenary = FmuStepper(catenary_fmu, step_size=step,
                          inputs=["contact_force", "contact_position"],
                          outputs=["contact_wire_height"],
                          parameters={"line": str(line.source), "time_step": TIME_STEP,
                                      "element_length": 2.0})
    pantograph = FmuStepper(pantograph_fmu, step_size=step, inputs=["eta"], outputs=["F_c"],
                            parameters=setup.fmu_parameters(line.contact_wire_height,
                                                            SPEED_KMH))
    with catenary, pantograph:
        wire = catenary.initialise([0.0, 0.0])[0]
        forces = [pantograph.initialise([wire])[0]]
        for n in range(1, int(stop / (speed * step) + 1e-9) + 1):
            force = max(pantograph.step([wire])[0], 0.0)
            wire = catenary.step([force, min(n * speed * step, stop)])[0]
            forces.append(force)
    return np.array(forces)


def test_catenary_fmu_matches_the_in_process_master(tmp_path, project_fmus, short_line_file):
    fmu = build_catenary_fmu(tmp_path)
    assert fmu.name == "CatenaryFMU.fmu"
    line = load_line(short_line_file)
    setup = pantograph_setup("en50318-2002").with_fmu(project_fmus["TwoMass.fmu"].path)
    stop = 100.0
    in_process = cosimulate(line, setup, speed_kmh=SPEED_KMH, time_step=TIME_STEP,
                            communication_step=SUBSTEPS * TIME_STEP, element_length=2.0,
                            stop_position=stop)
    through_fmus = _fmu_master(fmu, setup.fmu_path, setup, line, stop)
    assert through_fmus.shape == in_process.contact_force.shape
    assert np.ptp(in_process.contact_force) > 20.0  # a real dynamic run, not a flat line
    np.testing.assert_allclose(through_fmus, in_process.contact_force, rtol=0, atol=1e-8)


def test_catenary_fmu_refuses_a_step_that_is_not_a_multiple(tmp_path, short_line_file):
    fmu = build_catenary_fmu(tmp_path)
    with FmuStepper(fmu, step_size=1.5 * TIME_STEP, inputs=["contact_force",
                                                             "contact_position"],
                    outputs=["contact_wire_height"],
                    parameters={"line": str(short_line_file), "time_step": TIME_STEP,
                                "element_length": 2.0}) as catenary:
        assert catenary.initialise([0.0, 10.0])[0] == pytest.approx(5.3, abs=0.05)
        with pytest.raises(RuntimeError, match="fmi2DoStep"):
            catenary.step([100.0, 10.0])
