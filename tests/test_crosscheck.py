"""Built FMUs outside fmpy: independent importers (ecospy, libcosimpy) and the toolbox's checker.

The toy (``tests/fixtures/toy_model.py``) is a linear mass-spring-damper with a contact spring,
so its free response from rest is known in closed form. Each independent run must reproduce
fmpy's trajectory of the same FMU and the analytic response; a refused value or a failing step
must surface as an error; the checker must accept the built FMUs and reject broken copies.
"""
from __future__ import annotations

import logging
import re
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

from panto.build_fmu import build_fmu
from panto.build_fmu.crosscheck import (ImporterRunError, UnknownVariableError, UnsupportedFmuError,
                                  check_fmu_with_toolbox, simulate_in_independent_importer)
from fixtures.toy_model import (ToyParameters, analytic_equilibrium, analytic_free_response,
                                      make_toy_spec)

STOP_TIME = 0.5
STEP_SIZE = 0.01
OUTPUTS = ["x", "F_c"]
#: Away from the FMU's start values (eta = 0.01 m, p = 4 bar), so ignored inputs show.
INPUTS = {"eta": 0.02, "p": 5.0}
#: FMU parameters, and the same physics for the analytic solution; both start from rest at z = 0.
SCENARIOS = {
    "stiffer-contact": ({"k": 800.0, "start_in_equilibrium": False}, ToyParameters(k=800.0)),
    "contact-off": ({"contact_active": False, "start_in_equilibrium": False},
                    ToyParameters(contact_active=False)),
}
RUNS = [
    pytest.param(2, "ecospy", id="fmi2-ecospy"),
    pytest.param(2, "libcosimpy", id="fmi2-libcosimpy"),
    pytest.param(3, "ecospy", id="fmi3-ecospy"),
]


@pytest.fixture(scope="session")
def toy_fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """The toy built by the project's builder, FMI 2.0 and FMI 3.0."""
    directory = tmp_path_factory.mktemp("crosscheck_fmus")
    return {version: build_fmu(make_toy_spec(), directory, fmi_version=version)
            for version in (2, 3)}


def simulate(fmu: Path, **arguments) -> dict[str, np.ndarray]:
    """The independent importer over the test's time grid, recording x and F_c by default."""
    return simulate_in_independent_importer(fmu, **{"stop_time": STOP_TIME, "step_size": STEP_SIZE,
                                                    "outputs": OUTPUTS, **arguments})


@pytest.fixture(scope="session")
def simulate_independently(toy_fmus) -> Callable[[int, str, str], dict[str, np.ndarray]]:
    """Run (FMI version, importer, scenario) once per session; a child process costs ~0.25 s."""
    results: dict[tuple[int, str, str], dict[str, np.ndarray]] = {}

    def run(version: int, importer: str, scenario: str) -> dict[str, np.ndarray]:
        if (version, importer, scenario) not in results:
            results[version, importer, scenario] = simulate(
                toy_fmus[version], inputs=INPUTS, parameters=SCENARIOS[scenario][0],
                importer=importer)
        return results[version, importer, scenario]

    return run


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("version, importer", RUNS)
def test_independent_importer_reproduces_fmpy(toy_fmus, simulate_independently, version, importer,
                                              scenario):
    parameters, _ = SCENARIOS[scenario]
    independent = simulate_independently(version, importer, scenario)
    reference = simulate_fmu(toy_fmus[version], fmi_type="CoSimulation", stop_time=STOP_TIME,
                             step_size=STEP_SIZE, output_interval=STEP_SIZE,
                             start_values={**parameters, **INPUTS}, output=OUTPUTS)
    np.testing.assert_allclose(independent["time"], reference["time"], rtol=0, atol=1e-12)
    for name in OUTPUTS:
        scale = max(np.ptp(reference[name]), 1e-12)  # F_c is identically 0 with the contact off
        np.testing.assert_allclose(independent[name], reference[name], rtol=0, atol=1e-6 * scale,
                                   err_msg=name)


@pytest.mark.parametrize("scenario", SCENARIOS)
@pytest.mark.parametrize("version, importer", RUNS)
def test_independent_importer_follows_analytic_response(simulate_independently, version, importer,
                                                        scenario):
    physics = SCENARIOS[scenario][1]
    result = simulate_independently(version, importer, scenario)
    z_equilibrium = analytic_equilibrium(physics, **INPUTS)
    expected = analytic_free_response(physics, z_equilibrium, 0.0, 0.0, result["time"])
    assert np.ptp(expected) > 0.5 * z_equilibrium  # a real transient, not a resting mass
    np.testing.assert_allclose(result["x"], expected, rtol=0, atol=1e-4 * z_equilibrium)
    expected_force = physics.contact_stiffness * (result["x"] - INPUTS["eta"])
    np.testing.assert_allclose(result["F_c"], expected_force, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("version, importer", RUNS)
def test_refused_parameter_is_an_error(toy_fmus, version, importer):
    with pytest.raises(ImporterRunError, match=r"\bm\b.*-1"):
        simulate(toy_fmus[version], parameters={"m": -1.0}, importer=importer)


@pytest.mark.parametrize("version, importer", RUNS)
def test_failing_step_is_an_error(toy_fmus, version, importer):
    """The toy's C code fails once the mass leaves its travel x_max (ecos would step on)."""
    with pytest.raises(ImporterRunError, match="left its travel"):
        simulate(toy_fmus[version], parameters={"x_max": 0.001, "start_in_equilibrium": False},
                 importer=importer)


def test_fmi2_description_leaves_time_implicit_and_libcosimpy_loads_it_silently(toy_fmus, caplog):
    """FMI 2.0.4 section 2.2.7: without an independent variable, ``time`` (unit s) is implicit.
    A listed one without start value (the standard forbids one) made FMI Library in libcosim warn
    'Start attribute is required for this causality, variability and initial combination'."""
    with zipfile.ZipFile(toy_fmus[2]) as fmu:
        xml = fmu.read("modelDescription.xml").decode("utf-8")
    assert 'causality="independent"' not in xml
    with caplog.at_level(logging.WARNING, logger="panto.build_fmu.crosscheck"):
        result = simulate(toy_fmus[2], importer="libcosimpy")
    assert [record.getMessage() for record in caplog.records] == []
    assert np.all(np.isfinite(result["x"]))


def test_libcosimpy_refuses_fmi3_before_loading_it(toy_fmus):
    with pytest.raises(UnsupportedFmuError, match="FMI 3.0"):
        simulate(toy_fmus[3], importer="libcosimpy")


@pytest.mark.parametrize("arguments, message", [
    pytest.param({"outputs": ["x", "nope"]}, r"\['nope'\]", id="unknown-output"),
    pytest.param({"inputs": {"k": 1.0}}, "no input variable named 'k'",
                 id="parameter-given-as-input"),
    pytest.param({"parameters": {"eta": 1.0}}, "no parameter variable named 'eta'",
                 id="input-given-as-parameter"),
])
def test_wrong_names_are_refused_with_the_name(toy_fmus, arguments, message):
    with pytest.raises(UnknownVariableError, match=message):
        simulate(toy_fmus[2], **arguments)


def test_stop_time_must_be_a_whole_number_of_steps(toy_fmus):
    with pytest.raises(ValueError, match="multiple"):
        simulate(toy_fmus[2], stop_time=0.105, step_size=0.01)


@pytest.mark.parametrize("version", [2, 3], ids=["fmi2", "fmi3"])
def test_checker_accepts_built_fmus(toy_fmus, version):
    assert check_fmu_with_toolbox(toy_fmus[version]) == []


def _drop_first_output(xml: str) -> str:
    """Remove the first entry of <Outputs> (FMI 2.0) or the first <Output> (FMI 3.0): x's."""
    return re.sub(r"<(Unknown|Output) [^>]*/>", "", xml, count=1)


CORRUPTIONS: dict[str, tuple[Callable[[str], str], str]] = {
    "invalid-causality": (lambda xml: xml.replace('causality="input"', 'causality="sometimes"', 1),
                          "causality='sometimes'"),
    "duplicate-name": (lambda xml: xml.replace('name="F_c"', 'name="x"'),
                       "Name 'x' is used by several variables"),
    "output-not-in-model-structure": (_drop_first_output, "Output 'x' is not listed"),
    "not-well-formed": (lambda xml: xml[: len(xml) // 2], "not well-formed"),
}


@pytest.mark.parametrize("corruption", CORRUPTIONS)
@pytest.mark.parametrize("version", [2, 3], ids=["fmi2", "fmi3"])
def test_checker_rejects_broken_model_description(toy_fmus, tmp_path, version, corruption):
    edit, expected = CORRUPTIONS[corruption]
    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(toy_fmus[version]) as source, zipfile.ZipFile(broken, "w") as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename == "modelDescription.xml":
                edited = edit(data.decode("utf-8"))
                assert edited != data.decode("utf-8"), "the corruption did not apply"
                data = edited.encode("utf-8")
            target.writestr(item, data)
    problems = check_fmu_with_toolbox(broken)
    assert any(expected in problem for problem in problems), problems


def test_checker_needs_an_existing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.fmu"):
        check_fmu_with_toolbox(tmp_path / "missing.fmu")
