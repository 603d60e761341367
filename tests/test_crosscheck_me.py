"""FMI 3.0 Model Exchange in a second importer (issue 22): the FMU Manipulation Toolbox's container
integrates the product's FMI 3.0 FMUs through their Model Exchange interface with its own RK4.

Reference: fmpy's Model Exchange run of the same FMU with CVODE at a relative tolerance of 1e-12,
the inputs as a staircase (a value per 10 ms held over the step, the jumps as input events),
exactly what the container receives at its communication points. The container's fixed-step RK4
is of order 4: halving its step divides its error by 16 once the step is small enough, so the
ratio of the differences to the reference at 2 ms and 1 ms must lie between 12 and 20 (order
3.6 to 4.3; measured 15.8 to 16.2 on all eight FMI 3.0 FMUs, where a reference at 1e-10 left a
floor that brought it down to 8). An importer or an ME interface that got the derivatives, the
states or the inputs' timing wrong would not converge to fmpy's solution at that rate. The
difference at 1 ms must also be below 1e-4 of each output's range (measured 2e-8 to 6e-6).
"""
from __future__ import annotations

import re
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from panto.build_fmu.crosscheck import UnsupportedFmuError
from panto.build_fmu.crosscheck_me import model_exchange_only, simulate_model_exchange_in_container

STOP_TIME = 0.5
STEP_SIZE = 0.01
TIMES = np.linspace(0.0, STOP_TIME, round(STOP_TIME / STEP_SIZE) + 1)
AMPLITUDES = {"eta": 0.01, "F_c": 20.0, "p": 0.5, "M_b": 20.0}
#: Container steps (s): the two of the convergence check.
SOLVER_STEPS = (2e-3, 1e-3)
#: A linear oscillator and the nonlinear pantograph, each displacement- and force-excited.
FILES = ["TwoMass_fmi3.fmu", "ThreeMassForce_fmi3.fmu", "Pantograph_fmi3.fmu",
         "PantographForce_fmi3.fmu"]


@pytest.fixture(scope="module")
def fmus(project_fmus, force_fmus):
    """The session's FMUs by file name."""
    return {name: built.path for name, built in {**project_fmus, **force_fmus}.items()}


def excitation(path) -> dict[str, np.ndarray]:
    """A 3 Hz sine on the first input, a step at 0.2 s on the second, at the communication points."""
    first, second = (v for v in read_model_description(str(path)).modelVariables
                     if v.causality == "input")
    return {first.name: float(first.start) + AMPLITUDES[first.name] * np.sin(6 * np.pi * TIMES),
            second.name: float(second.start) + AMPLITUDES[second.name] * (TIMES >= 0.2 - 1e-9)}


def fmpy_model_exchange(path, inputs: dict[str, np.ndarray], outputs: list[str]):
    """fmpy's ME run with the inputs held over each communication step; the outputs at the
    communication points just before the inputs jump (as a co-simulation records them)."""
    rows = [(0.0, *[values[0] for values in inputs.values()])]
    for k in range(1, TIMES.size):
        rows.append((TIMES[k], *[values[k - 1] for values in inputs.values()]))
        rows.append((TIMES[k], *[values[k] for values in inputs.values()]))
    table = np.array(rows, dtype=[("time", float)] + [(name, float) for name in inputs])
    result = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=STOP_TIME,
                          output_interval=STEP_SIZE, input=table, output=outputs,
                          solver="CVode", relative_tolerance=1e-12)
    first = [int(np.flatnonzero(np.isclose(result["time"], t, rtol=0, atol=1e-12))[0])
             for t in TIMES]
    return {name: result[name][first] for name in outputs}


@pytest.mark.parametrize("file", FILES)
def test_container_integrates_the_fmi3_model_exchange_interface_like_fmpy(fmus, file):
    path = fmus[file]
    outputs = [v.name for v in read_model_description(str(path)).modelVariables
               if v.causality == "output"]
    inputs = excitation(path)
    reference = fmpy_model_exchange(path, inputs, outputs)
    differences = []
    for solver_step in SOLVER_STEPS:
        result = simulate_model_exchange_in_container(
            path, stop_time=STOP_TIME, step_size=STEP_SIZE, outputs=outputs, inputs=inputs,
            solver_step=solver_step)
        np.testing.assert_allclose(result["time"], TIMES, rtol=0, atol=1e-12)
        differences.append(max(np.max(np.abs(result[name] - reference[name]))
                               / np.ptp(reference[name]) for name in outputs))
    coarse, fine = differences
    assert fine <= 1e-4, differences
    assert 12.0 <= coarse / fine <= 20.0, differences


def test_the_embedded_copy_offers_model_exchange_only(fmus, tmp_path):
    copy = model_exchange_only(fmus["TwoMass_fmi3.fmu"], tmp_path / "me.fmu")
    description = read_model_description(str(copy))
    assert description.coSimulation is None and description.modelExchange is not None
    with zipfile.ZipFile(copy) as archive, zipfile.ZipFile(fmus["TwoMass_fmi3.fmu"]) as original:
        assert set(archive.namelist()) == set(original.namelist())  # binaries and sources kept


def test_a_co_simulation_only_fmu_is_refused(fmus, tmp_path):
    source = fmus["TwoMass_fmi3.fmu"]
    co_simulation_only = tmp_path / "cs.fmu"
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(co_simulation_only, "w") as copy:
        for item in original.infolist():
            data = original.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode("utf-8")
                edited = re.sub(r"<ModelExchange [^>]*/>", "", text)  # FMI 3.0: no children
                assert edited != text
                data = edited.encode("utf-8")
            copy.writestr(item, data)
    with pytest.raises(UnsupportedFmuError, match="no Model Exchange"):
        simulate_model_exchange_in_container(co_simulation_only, stop_time=0.1, step_size=0.01,
                                             outputs=["xi"])
