"""The product's FMUs in the independent importers (issue 22): ecospy (FMI 2.0 and 3.0
Co-Simulation) and libcosimpy (FMI 2.0 Co-Simulation) against fmpy.

Every FMU of ``panto build-fmu`` (displacement- and force-excited, FMI 2.0 and 3.0) runs 0.5 s
in 10 ms communication steps with both inputs varying: the first a 3 Hz sine about its start
value, the second a step at 0.2 s (eta or the contact force, and the pressure or the bellow
torque). Each importer receives the same samples at the communication points and holds them
over the step, as fmpy does for an FMU that cannot interpolate its inputs.

Tolerance: 1e-9 of each output's range. The three importers call the same compiled code with
the same values and step sizes; what may differ is the rounding of the communication points
(fmpy adds h to the time, libcosim counts integer nanoseconds), which moves the FMU's internal
integration grid by about 1e-16 s. Measured: at most 3e-12 of the range (PantographForce's head
velocity). A wrong input timing (the value of the previous or next step) departs by more than
1e-3 of the range, which the last test checks for every FMU.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from panto.build_fmu.crosscheck import simulate_in_independent_importer
from panto.fmu_src.models import DISPLACEMENT_FMU_NAMES, FORCE_FMU_NAMES

STOP_TIME = 0.5
STEP_SIZE = 0.01
TIMES = np.linspace(0.0, STOP_TIME, round(STOP_TIME / STEP_SIZE) + 1)
#: Amplitude of each input's excursion from its start value (m, N, bar, N m): a few per cent of
#: the operating point, well inside the admissible ranges, so no contact is lost.
AMPLITUDES = {"eta": 0.01, "F_c": 20.0, "p": 0.5, "M_b": 20.0}
TOLERANCE = 1e-9
FILES = [f"{name}{suffix}.fmu" for name in DISPLACEMENT_FMU_NAMES + FORCE_FMU_NAMES
         for suffix in ("", "_fmi3")]
RUNS = [pytest.param(file, importer, id=f"{file.removesuffix('.fmu')}-{importer}")
        for file in FILES for importer in ("ecospy", "libcosimpy")
        if importer == "ecospy" or not file.endswith("_fmi3.fmu")]


@pytest.fixture(scope="module")
def fmus(project_fmus, force_fmus) -> dict[str, Path]:
    """Every FMU of ``panto build-fmu`` by file name (the session's builds)."""
    return {name: built.path for name, built in {**project_fmus, **force_fmus}.items()}


def excitation(path: Path, delay: int = 0) -> dict[str, np.ndarray]:
    """The inputs at the communication points: a sine on the first, a step on the second;
    `delay` communication steps late (the start values before)."""
    inputs = [v for v in read_model_description(str(path)).modelVariables
              if v.causality == "input"]
    assert len(inputs) == 2, [v.name for v in inputs]
    late = np.maximum(TIMES - delay * STEP_SIZE, 0.0)
    sine, step = (AMPLITUDES[v.name] for v in inputs)
    return {inputs[0].name: float(inputs[0].start) + sine * np.sin(2 * np.pi * 3.0 * late),
            inputs[1].name: float(inputs[1].start) + step * (late >= 0.2 - 1e-9)}


def outputs(path: Path) -> list[str]:
    """The FMU's output names."""
    return [v.name for v in read_model_description(str(path)).modelVariables
            if v.causality == "output"]


def run_fmpy(path: Path, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """fmpy's co-simulation with the inputs as a table at the communication points."""
    table = np.array(list(zip(TIMES, *inputs.values())),
                     dtype=[("time", float)] + [(name, float) for name in inputs])
    result = simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=STOP_TIME,
                          step_size=STEP_SIZE, output_interval=STEP_SIZE, input=table,
                          output=outputs(path))
    return {name: result[name] for name in result.dtype.names}


def largest_difference(result: dict[str, np.ndarray], reference: dict[str, np.ndarray],
                       names: list[str]) -> float:
    """The largest difference of any output, as a fraction of that output's range."""
    return max(float(np.max(np.abs(result[name] - reference[name])) / np.ptp(reference[name]))
               for name in names)


@pytest.mark.parametrize("file, importer", RUNS)
def test_importer_runs_the_fmu_like_fmpy(fmus, caplog, file, importer):
    path = fmus[file]
    names = outputs(path)
    reference = run_fmpy(path, excitation(path))
    with caplog.at_level(logging.WARNING, logger="panto.build_fmu.crosscheck"):
        result = simulate_in_independent_importer(path, stop_time=STOP_TIME, step_size=STEP_SIZE,
                                                  inputs=excitation(path), outputs=names,
                                                  importer=importer)
    assert [record.getMessage() for record in caplog.records] == []  # no warning, no error
    np.testing.assert_allclose(result["time"], reference["time"], rtol=0, atol=1e-12)
    for name in names:
        assert np.ptp(reference[name]) > 0, name  # every output moves
    assert largest_difference(result, reference, names) <= TOLERANCE


@pytest.mark.parametrize("file", FILES)
def test_the_comparison_sees_an_input_one_step_late(fmus, file):
    """The agreement above is not a coincidence of slow signals: the same run with the inputs
    one communication step late (or early) departs from it far beyond the tolerance."""
    path = fmus[file]
    names = outputs(path)
    reference = run_fmpy(path, excitation(path))
    for delay in (1, -1):
        assert largest_difference(run_fmpy(path, excitation(path, delay)), reference,
                                  names) > 1e6 * TOLERANCE, delay
