"""The hand-written FMU runtime and the FMU builder, checked on toy models with known answers.

The toy (``tests/fixtures/toy_model.py``) is a mass on a spring and damper, pushed by
``gain * p`` and touching the contact line ``eta`` through ``k_E``; it is linear, so its
equilibrium, its matrices A, B, C, D and its free response are known in closed form. Its FMUs
(FMI 2.0 and 3.0, nonlinear and linearised) are built once per session. A second model with a
configuration-dependent mass matrix checks the exact Jacobian against finite differences.
"""
from __future__ import annotations

import ctypes
import dataclasses
import math
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import fmi3DependencyKind, fmi3ValueReference
from fmpy.simulation import instantiate_fmu

from panto.build_fmu import (CompilationError, build_fmu, derive_instantiation_token,
                       divide_unit_by_time, layout_variables, parse_unit, validate_fmu)
from panto.build_fmu.compile import COMPILER_FLAGS, find_compiler
from fixtures.toy_model import (ToyParameters, analytic_equilibrium,
                                      analytic_free_response, analytic_matrices, make_toy_spec,
                                      make_variable_mass_spec)

VERSIONS = [2, 3]
VARIANTS = ["nonlinear", "linear"]
INTERFACES = ["ModelExchange", "CoSimulation"]
DEFAULTS = ToyParameters()


@dataclass(frozen=True)
class BuiltFmu:
    """A built FMU, unpacked once, with its value references by name."""

    path: Path
    version: int
    linearised: bool
    unzipdir: str

    @property
    def description(self):
        return read_model_description(str(self.path))

    @property
    def vr(self) -> dict[str, int]:
        return {v.name: v.valueReference for v in self.description.modelVariables}


@pytest.fixture(scope="session")
def fmus(tmp_path_factory) -> dict[tuple[int, str], BuiltFmu]:
    directory = tmp_path_factory.mktemp("toy_fmus")
    built = {}
    for version in VERSIONS:
        for variant in VARIANTS:
            path = build_fmu(make_toy_spec(linearised=variant == "linear"), directory,
                             fmi_version=version)
            built[version, variant] = BuiltFmu(path, version, variant == "linear",
                                               extract(str(path)))
        path = build_fmu(make_variable_mass_spec(), directory, fmi_version=version)
        built[version, "variable_mass"] = BuiltFmu(path, version, False, extract(str(path)))
    return built


class LogRecorder:
    """fmpy logger callback (FMI 2 and 3 signatures) keeping the messages as text."""

    def __init__(self) -> None:
        self.messages: list[str] = []

    def __call__(self, *arguments) -> None:
        self.messages.append(arguments[-1].decode())

    def text(self) -> str:
        return "\n".join(self.messages)


class Instance:
    """A thin version-independent driver of one fmpy instance of a toy FMU."""

    def __init__(self, fmu: BuiltFmu, interface: str = "CoSimulation",
                 debug_logging: bool = False) -> None:
        self.fmu, self.vr, self.log = fmu, fmu.vr, LogRecorder()
        self.raw = instantiate_fmu(fmu.unzipdir, fmu.description, interface, logger=self.log,
                                   debug_logging=debug_logging)
        self.time = 0.0

    def set(self, **values: float) -> None:
        for name, value in values.items():
            if isinstance(value, bool):
                self.raw.setBoolean([self.vr[name]], [value])
            elif self.fmu.version == 2:
                self.raw.setReal([self.vr[name]], [value])
            else:
                self.raw.setFloat64([self.vr[name]], [value])

    def get(self, *names: str) -> np.ndarray:
        vrs = [self.vr[name] for name in names]
        values = self.raw.getReal(vrs) if self.fmu.version == 2 else self.raw.getFloat64(vrs)
        return np.array(values)

    def initialize(self, **values: float) -> Instance:
        if self.fmu.version == 2:
            self.raw.setupExperiment(startTime=0.0)
        self.set(**values)
        self.raw.enterInitializationMode()
        self.raw.exitInitializationMode()
        return self

    def step(self, h: float) -> None:
        self.raw.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time += h

    def jacobian(self, unknowns: list[str], knowns: list[str], adjoint: bool = False):
        """Matrix d unknowns / d knowns, one seed vector at a time."""
        u_vr, k_vr = [self.vr[n] for n in unknowns], [self.vr[n] for n in knowns]
        if adjoint:
            rows = [self.raw.getAdjointDerivative(u_vr, k_vr, np.eye(len(unknowns))[i],
                                                  nSensitivity=len(knowns))
                    for i in range(len(unknowns))]
            return np.array(rows)
        columns = [self.raw.getDirectionalDerivative(u_vr, k_vr, list(np.eye(len(knowns))[j]))
                   for j in range(len(knowns))]
        return np.array(columns).T

    def set_states(self, x: list[float]) -> None:
        self.raw.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))

    def derivatives(self, n: int) -> np.ndarray:
        buffer = (ctypes.c_double * n)()
        if self.fmu.version == 2:
            self.raw.getDerivatives(buffer, n)
        else:
            self.raw.getContinuousStateDerivatives(buffer, n)
        return np.array(buffer)

    def close(self) -> None:
        self.raw.freeInstance()


def state_names(fmu: BuiltFmu) -> tuple[str, str]:
    return ("delta_z", "delta_v") if fmu.linearised else ("z", "v")


def ids(version: int, variant: str) -> str:
    return f"fmi{version}-{variant}"


ALL_TOYS = [pytest.param(v, k, id=ids(v, k)) for v in VERSIONS for k in VARIANTS]
ALL_RUNS = [pytest.param(v, k, i, id=f"{ids(v, k)}-{i}") for v in VERSIONS for k in VARIANTS
            for i in INTERFACES]


# --- builder ---------------------------------------------------------------------------------

@pytest.mark.parametrize("version, variant", ALL_TOYS + [
    pytest.param(v, "variable_mass", id=ids(v, "variable_mass")) for v in VERSIONS])
def test_validator_reports_nothing(fmus, version, variant):
    assert validate_fmu(fmus[version, variant].path) == []


@pytest.mark.parametrize("unit, factor, exponents", [
    ("m", 1.0, {"m": 1}),
    ("rad/s", 1.0, {"rad": 1, "s": -1}),
    ("N.m.s/rad", 1.0, {"kg": 1, "m": 2, "s": -1, "rad": -1}),
    ("kg.m2", 1.0, {"kg": 1, "m": 2}),
    ("N/m", 1.0, {"kg": 1, "s": -2}),
    ("bar", 1e5, {"kg": 1, "m": -1, "s": -2}),
    ("N/bar", 1e-5, {"m": 2}),
    ("1", 1.0, {}),
], ids=lambda value: str(value) if isinstance(value, str) else None)
def test_units_translate_to_si_base_units(unit, factor, exponents):
    definition = parse_unit(unit)
    assert definition.factor == pytest.approx(factor, rel=1e-15)
    assert dict(definition.exponents) == exponents


@pytest.mark.parametrize("unit, derivative", [("m", "m/s"), ("m/s", "m/s2"), ("rad", "rad/s"),
                                              ("1", "1/s"), ("N.s", "N")])
def test_time_derivative_units(unit, derivative):
    assert divide_unit_by_time(unit) == derivative


def test_unknown_unit_is_refused_with_its_name():
    with pytest.raises(ValueError, match="furlong"):
        parse_unit("furlong/s")


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_description_carries_units_ranges_and_runtime_parameters(fmus, version):
    description = fmus[version, "linear"].description
    variables = {v.name: v for v in description.modelVariables}
    assert {u.name for u in description.unitDefinitions} >= {"m", "bar", "N/m", "N.s/m"}
    bar = next(u for u in description.unitDefinitions if u.name == "bar")
    assert bar.baseUnit.factor == 1e5 and (bar.baseUnit.kg, bar.baseUnit.m, bar.baseUnit.s) == (
        1, -1, -2)
    assert all(v.unit for v in description.modelVariables if v.type in ("Real", "Float64"))
    assert (float(variables["m"].min), float(variables["m"].max)) == (1e-3, 1e3)
    assert variables["delta_z"].causality == "local" and variables["der(delta_z)"].derivative
    assert variables["eta0"].causality == "parameter" and variables["eta0"].unit == "m"
    assert variables["p0"].unit == "bar"
    assert variables["solver_tolerance"].start == "1e-06"
    assert variables["start_in_equilibrium"].type == "Boolean"


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_binary_exports_only_fmi_functions(fmus, version):
    fmu = fmus[version, "nonlinear"]
    library = ctypes.CDLL(next(Path(fmu.unzipdir, "binaries").rglob("*.so")).as_posix())
    assert hasattr(library, f"fmi{version}Instantiate" if version == 2 else
                   "fmi3InstantiateCoSimulation")
    assert not hasattr(library, "model_forces") and not hasattr(library, "core_do_step")


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_runtime_compiles_without_warnings(fmus, version):
    sources = Path(fmus[version, "linear"].unzipdir, "sources")
    command = [find_compiler(), *COMPILER_FLAGS, "-Werror", "-fsyntax-only", "-I", str(sources),
               *map(str, sorted(sources.glob("*.c")))]
    result = subprocess.run(command, capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr


def test_instantiation_token_follows_the_content():
    spec = make_toy_spec()
    token = derive_instantiation_token(spec, layout_variables(spec), 2)
    assert token == derive_instantiation_token(spec, layout_variables(spec), 2)
    assert token != derive_instantiation_token(spec, layout_variables(spec), 3)
    changed = dataclasses.replace(spec, c_code=spec.c_code + "\n")
    assert token != derive_instantiation_token(changed, layout_variables(changed), 2)


def test_compiler_failure_is_reported_with_its_output(tmp_path):
    broken = dataclasses.replace(make_toy_spec(), c_code="int model_forces(void) { oops }")
    with pytest.raises(CompilationError, match="oops"):
        build_fmu(broken, tmp_path, fmi_version=2)


@pytest.mark.parametrize("name, message", [("k", "outside its range"), ("x", "used by both")])
def test_inconsistent_spec_is_refused_before_compiling(name, message):
    spec = make_toy_spec()
    if name == "k":
        parameters = tuple(dataclasses.replace(p, value=-1.0) if p.name == "k" else p
                           for p in spec.parameters)
        spec = dataclasses.replace(spec, parameters=parameters)
    else:
        spec = dataclasses.replace(spec, coordinates=(dataclasses.replace(
            spec.coordinates[0], name="x"),))
    with pytest.raises(ValueError, match=message):
        layout_variables(spec)


# --- physics: equilibrium, step response, free response --------------------------------------

@pytest.mark.parametrize("version, variant, interface", ALL_RUNS)
def test_starts_and_stays_in_the_analytic_equilibrium(fmus, version, variant, interface):
    changes = {"k": 2000.0, "eta": 0.02, "p": 3.0}
    result = simulate_fmu(str(fmus[version, variant].path), fmi_type=interface, stop_time=0.2,
                          start_values=changes, output=["x", "F_c"])
    parameters = ToyParameters(k=2000.0)
    x_eq = analytic_equilibrium(parameters, 0.02, 3.0)
    np.testing.assert_allclose(result["x"], x_eq, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result["F_c"], DEFAULTS.k_E * (x_eq - 0.02), rtol=1e-9)


def step_inputs(t_step: float, before: tuple[float, float], after: tuple[float, float]):
    rows = [(0.0, *before), (t_step, *before), (t_step, *after), (1.0, *after)]
    return np.array(rows, dtype=[("time", float), ("eta", float), ("p", float)])


@pytest.mark.parametrize("version, variant, interface", ALL_RUNS)
def test_step_response_matches_the_analytic_solution(fmus, version, variant, interface):
    t_step, before, after = 0.05, (0.01, 4.0), (0.004, 6.0)
    options = {"relative_tolerance": 1e-9} if interface == "ModelExchange" else {}
    start_values = {"solver_tolerance": 1e-9}
    if variant == "linear":
        start_values |= {"eta0": 0.0, "p0": 1.0}  # linearised away from the inputs
    result = simulate_fmu(str(fmus[version, variant].path), fmi_type=interface, stop_time=0.4,
                          output_interval=1e-3, input=step_inputs(t_step, before, after),
                          start_values=start_values, output=["x", "F_c"], **options)
    x_before = analytic_equilibrium(DEFAULTS, *before)
    x_after = analytic_equilibrium(DEFAULTS, *after)
    t = result["time"]
    expected = np.where(t <= t_step, x_before, analytic_free_response(
        DEFAULTS, x_after, x_before, 0.0, np.maximum(t - t_step, 0.0)))
    amplitude = abs(x_after - x_before)
    np.testing.assert_allclose(result["x"], expected, rtol=0, atol=2e-5 * amplitude)


@pytest.mark.parametrize("version, variant, interface", ALL_RUNS)
def test_state_start_values_are_honoured_without_equilibrium(fmus, version, variant, interface):
    fmu = fmus[version, variant]
    z0, v0 = 0.002, 0.1
    position, velocity = state_names(fmu)
    offset = analytic_equilibrium(DEFAULTS, 0.01, 4.0) if fmu.linearised else 0.0
    result = simulate_fmu(str(fmu.path), fmi_type=interface, stop_time=0.3, output_interval=1e-3,
                          relative_tolerance=1e-9, output=["x", position, velocity],
                          start_values={"start_in_equilibrium": False, position: z0 - offset,
                                        velocity: v0, "solver_tolerance": 1e-9})
    assert result["x"][0] == pytest.approx(z0, abs=1e-15)
    assert result[velocity][0] == pytest.approx(v0, abs=1e-15)
    expected = analytic_free_response(DEFAULTS, analytic_equilibrium(DEFAULTS, 0.01, 4.0), z0, v0,
                                      result["time"])
    np.testing.assert_allclose(result["x"], expected, rtol=0, atol=1e-7)


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
@pytest.mark.parametrize("damping", [5.0, 5e4], ids=["lightly-damped", "overdamped-stiff"])
def test_stiff_contact_is_integrated_accurately(fmus, version, damping):
    parameters = ToyParameters(k_E=1e6, c=damping)
    instance = Instance(fmus[version, "nonlinear"]).initialize(
        k_E=1e6, c=damping, start_in_equilibrium=False, z=0.0, solver_tolerance=1e-8)
    a, b, _, _ = analytic_matrices(parameters)
    x_eq = np.array([analytic_equilibrium(parameters, 0.01, 4.0), 0.0])
    for _ in range(50):
        instance.step(1e-3)
    expected = x_eq + scipy.linalg.expm(a * instance.time) @ (np.zeros(2) - x_eq)
    scale = x_eq[0] * np.array([1.0, math.sqrt(-a[1, 0])])  # displacement, velocity
    assert np.all(np.abs(instance.get("z", "v") - expected) < 1e-5 * scale)
    instance.close()


@pytest.mark.parametrize("version, interface", [(v, i) for v in VERSIONS for i in INTERFACES],
                         ids=[f"fmi{v}-{i}" for v in VERSIONS for i in INTERFACES])
def test_boolean_parameter_switches_the_contact_off(fmus, version, interface):
    result = simulate_fmu(str(fmus[version, "nonlinear"].path), fmi_type=interface,
                          stop_time=0.1, start_values={"contact_active": False},
                          output=["x", "F_c"])
    x_eq = analytic_equilibrium(ToyParameters(contact_active=False), 0.01, 4.0)
    np.testing.assert_allclose(result["x"], x_eq, atol=1e-12)
    np.testing.assert_allclose(result["F_c"], 0.0, atol=0.0)


# --- exact derivatives -----------------------------------------------------------------------

@pytest.mark.parametrize("version, variant", ALL_TOYS)
@pytest.mark.parametrize("interface", INTERFACES)
def test_directional_derivatives_equal_the_analytic_matrices(fmus, version, variant, interface):
    fmu = fmus[version, variant]
    parameters = ToyParameters(m=3.0, k=1500.0, c=7.0, gain=12.0, k_E=8000.0)
    instance = Instance(fmu, interface).initialize(m=3.0, k=1500.0, c=7.0, gain=12.0,
                                                   k_E=8000.0, eta=0.03, p=2.0)
    states = list(state_names(fmu))
    unknowns = [f"der({s})" for s in states] + ["x", "F_c"]
    jacobian = instance.jacobian(unknowns, states + ["eta", "p"])
    a, b, c, d = analytic_matrices(parameters)
    np.testing.assert_allclose(jacobian, np.block([[a, b], [c, d]]), rtol=1e-12, atol=1e-12)
    if version == 3:
        adjoint = instance.jacobian(unknowns, states + ["eta", "p"], adjoint=True)
        np.testing.assert_allclose(adjoint, jacobian, rtol=1e-12, atol=1e-12)
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_jacobian_with_state_dependent_mass_matches_finite_differences(fmus, version):
    instance = Instance(fmus[version, "variable_mass"], "ModelExchange").initialize()
    assert np.max(np.abs(instance.derivatives(4))) < 1e-9  # started in static equilibrium
    assert np.all(np.abs(instance.get("q1", "q2")) > 1e-3)
    instance.raw.enterContinuousTimeMode()
    x0, u0 = np.array([0.3, -0.2, 0.5, -0.7]), instance.get("u1", "u2")
    names, h = ["q1", "q2", "v1", "v2", "u1", "u2"], 1e-6

    def evaluate(x, u):
        instance.set_states(list(x))
        instance.set(u1=u[0], u2=u[1])
        return np.concatenate([instance.derivatives(4), instance.get("y1", "y2")])

    columns = []
    for j in range(6):
        e = np.eye(6)[j] * h
        columns.append((evaluate(x0 + e[:4], u0 + e[4:]) - evaluate(x0 - e[:4], u0 - e[4:]))
                       / (2 * h))
    evaluate(x0, u0)
    exact = instance.jacobian(["der(q1)", "der(q2)", "der(v1)", "der(v2)", "y1", "y2"], names)
    np.testing.assert_allclose(exact, np.array(columns).T, rtol=1e-6, atol=1e-6)
    instance.close()


# --- FMU state -------------------------------------------------------------------------------

def run_steps(instance: Instance, n: int) -> np.ndarray:
    outputs = []
    for _ in range(n):
        instance.set(eta=0.01 + 0.005 * math.sin(40.0 * instance.time))
        instance.step(2e-3)
        outputs.append(instance.get("x", "F_c"))
    return np.array(outputs)


@pytest.mark.parametrize("version, variant", ALL_TOYS)
def test_fmu_state_restores_a_trajectory_exactly(fmus, version, variant):
    instance = Instance(fmus[version, variant]).initialize(p=5.0)
    run_steps(instance, 20)
    state, time = instance.raw.getFMUState(), instance.time
    first = run_steps(instance, 30)
    instance.raw.setFMUState(state)
    instance.time = time
    second = run_steps(instance, 30)
    np.testing.assert_array_equal(first, second)
    assert np.ptp(first[:, 0]) > 0  # the trajectory moved
    instance.raw.freeFMUState(state)
    instance.close()


@pytest.mark.parametrize("version, variant", ALL_TOYS)
def test_serialized_state_continues_in_a_fresh_instance(fmus, version, variant):
    original = Instance(fmus[version, variant]).initialize(p=5.0, k=1200.0)
    run_steps(original, 10)
    state, time = original.raw.getFMUState(), original.time
    serialized = original.raw.serializeFMUState(state)
    expected = run_steps(original, 15)
    fresh = Instance(fmus[version, variant]).initialize()
    restored = fresh.raw.deserializeFMUState(serialized)
    fresh.raw.setFMUState(restored)
    fresh.time = time
    np.testing.assert_array_equal(run_steps(fresh, 15), expected)
    for instance, snapshot in ((original, state), (fresh, restored)):
        instance.raw.freeFMUState(snapshot)
        instance.close()


# --- bad calls get errors, never crashes -----------------------------------------------------

@pytest.mark.parametrize("version, interface", [(v, i) for v in VERSIONS for i in INTERFACES],
                         ids=[f"fmi{v}-{i}" for v in VERSIONS for i in INTERFACES])
def test_parameter_outside_its_bounds_is_an_error(fmus, version, interface):
    log = LogRecorder()
    with pytest.raises(FMICallException):
        simulate_fmu(str(fmus[version, "nonlinear"].path), fmi_type=interface,
                     start_values={"m": -1.0}, logger=log)
    assert "'m'" in log.text() and "outside its admissible range" in log.text()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_rejected_value_leaves_the_instance_usable(fmus, version):
    instance = Instance(fmus[version, "nonlinear"]).initialize()
    with pytest.raises(FMICallException):
        instance.set(eta=float("nan"))
    assert "not a finite number" in instance.log.text()
    with pytest.raises(FMICallException):
        instance.set(k=1e9)
    assert instance.get("eta", "k").tolist() == [0.01, 1000.0]
    instance.step(1e-3)
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_calls_in_the_wrong_state_and_unknown_references_are_errors(fmus, version):
    instance = Instance(fmus[version, "nonlinear"])
    with pytest.raises(FMICallException):
        instance.step(1e-3)
    assert "not allowed in Instantiated" in instance.log.text()
    with pytest.raises(FMICallException):
        instance.raw.getReal([999]) if version == 2 else instance.raw.getFloat64([999])
    assert "unknown value reference 999" in instance.log.text()
    instance.initialize()
    with pytest.raises(FMICallException):
        instance.set(z=0.5)  # states are not settable after initialisation
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_wrong_instantiation_token_is_refused(fmus, version):
    fmu, log = fmus[version, "nonlinear"], LogRecorder()
    description = fmu.description
    description.guid = "{00000000-0000-0000-0000-000000000000}"
    with pytest.raises(Exception, match="[Ff]ailed to instantiate"):
        instantiate_fmu(fmu.unzipdir, description, "CoSimulation", logger=log)
    assert "does not match" in log.text()


def test_fmi3_unused_types_and_scheduled_execution_are_refused(fmus):
    instance = Instance(fmus[3, "nonlinear"]).initialize()
    for call in (lambda: instance.raw.getInt32([1]), lambda: instance.raw.setString([1], ["a"]),
                 lambda: instance.raw.getUInt64([1]), instance.raw.enterConfigurationMode):
        with pytest.raises(FMICallException):
            call()
    assert "no variables of type Int32" in instance.log.text()
    assert "no variables of type String" in instance.log.text()
    library = ctypes.CDLL(next(Path(fmus[3, "nonlinear"].unzipdir, "binaries").rglob("*.so"))
                          .as_posix())
    library.fmi3InstantiateScheduledExecution.restype = ctypes.c_void_p
    assert library.fmi3InstantiateScheduledExecution(*[None] * 10) is None
    instance.close()


def test_fmi3_variable_dependencies_match_the_model_structure(fmus):
    fmu = fmus[3, "nonlinear"]
    instance = Instance(fmu)
    raw, component = instance.raw, instance.raw.component
    for unknown in fmu.description.derivatives + fmu.description.outputs:
        vr, count = unknown.variable.valueReference, ctypes.c_size_t()
        raw.fmi3GetNumberOfVariableDependencies(component, vr, ctypes.byref(count))
        n = count.value
        independents = (fmi3ValueReference * n)()
        raw.fmi3GetVariableDependencies(component, vr, (ctypes.c_size_t * n)(), independents,
                                        (ctypes.c_size_t * n)(), (fmi3DependencyKind * n)(), n)
        assert sorted(independents) == sorted(v.valueReference for v in unknown.dependencies)
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_failing_model_in_co_simulation_reports_its_message(fmus, version):
    instance = Instance(fmus[version, "nonlinear"]).initialize(
        start_in_equilibrium=False, z=0.0, x_max=0.02)  # the overshoot leaves the travel
    with pytest.raises(FMICallException):
        for _ in range(100):
            instance.step(1e-3)
    assert "the mass left its travel" in instance.log.text()
    instance.raw.terminate()  # terminates cleanly from the error state
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_failing_model_in_model_exchange_reports_its_message(fmus, version):
    instance = Instance(fmus[version, "nonlinear"], "ModelExchange").initialize(x_max=0.1)
    instance.raw.enterContinuousTimeMode()
    instance.set_states([0.5, 0.0])
    with pytest.raises(FMICallException):
        instance.derivatives(2)
    assert "|z| = 0.5 m exceeds x_max = 0.1 m" in instance.log.text()
    instance.raw.terminate()
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_unreachable_equilibrium_fails_initialisation_with_the_model_message(fmus, version):
    instance = Instance(fmus[version, "nonlinear"])
    with pytest.raises(FMICallException):
        instance.initialize(x_max=0.001)  # the equilibrium (15 mm) lies outside the travel
    assert "static equilibrium" in instance.log.text()
    assert "the mass left its travel" in instance.log.text()
    instance.raw.reset()  # the instance can be reused after a reset
    instance.initialize()
    assert instance.get("x")[0] == pytest.approx(analytic_equilibrium(DEFAULTS, 0.01, 4.0))
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_root_cause_of_a_failure_is_in_the_last_message(fmus, version):
    """Importers such as libcosim show only the last message, even with debug logging on."""
    instance = Instance(fmus[version, "nonlinear"], debug_logging=True).initialize(
        start_in_equilibrium=False, z=0.0, x_max=0.02)
    with pytest.raises(FMICallException):
        for _ in range(100):
            instance.step(1e-3)
    assert "-> Error" in instance.log.messages[-1]
    assert "the mass left its travel" in instance.log.messages[-1]
    instance.close()


@pytest.mark.parametrize("version", VERSIONS, ids=lambda v: f"fmi{v}")
def test_failed_linearisation_is_reported_once_in_the_error_state(fmus, version):
    instance = Instance(fmus[version, "linear"])
    with pytest.raises(FMICallException):
        instance.initialize(x_max=0.001)  # the operating point lies outside the travel
    last = instance.log.messages[-1]
    assert "cannot linearise" in last and "the mass left its travel" in last
    count = len(instance.log.messages)
    for _ in range(3):
        with pytest.raises(FMICallException):
            instance.get("F_c")
    assert len(instance.log.messages) == count  # no new equilibrium solve, no repeated message
    instance.raw.reset()  # a reset forgets the failure
    instance.initialize()
    assert np.isfinite(instance.get("F_c")[0])
    instance.close()
