"""The project's FMUs declare exactly the dependencies their equations have, and offer Model
Exchange importers the contact events (issue 22).

Dependencies: the ``<ModelStructure>`` of every FMU is compared with the sparsity of the Jacobian
of ``[dx/dt; y]`` with respect to ``[x; u]`` measured by finite differences of the FMU's own
derivatives and outputs at a generic point (parameters that are zero by default, such as the
three-mass oscillator's upper dampers or the pantograph's cubic suspension, are made nonzero).
A dependency declared ``constant`` or ``tunable`` must have the same difference quotient at a
second, distant point (its coefficient does not depend on states or inputs).

Events: fmpy's Model Exchange run of an oscillator with unilateral contact, whose wire jumps up
faster than the head can follow, locates contact loss and re-contact at the instants where an
independent path (scipy's ``solve_ivp`` with root finding on the Python twin of the model) finds
them.
"""
from __future__ import annotations

import ctypes

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.simulation import instantiate_fmu
from scipy.integrate import solve_ivp

from panto.fmu_src.models import DISPLACEMENT_FMU_NAMES, FORCE_FMU_NAMES, Model

FILES = [f"{name}{suffix}.fmu" for name in DISPLACEMENT_FMU_NAMES + FORCE_FMU_NAMES
         for suffix in ("", "_fmi3")]
#: Parameters set away from zero so that no dependency vanishes by accident of the defaults.
GENERIC_PARAMETERS = {
    "Pantograph": {"T_f": 5.0, "kappa_p": 0.3, "k_c3": 1e6, "alpha": 0.05},
    "TwoMass": {"F_f1": 3.0, "F_f2": 2.0, "p_gain": 40.0},
    "ThreeMass": {"c2": 37.0, "c3": 11.0, "F_f1": 3.0, "F_f2": 2.0, "F_f3": 1.0, "p_gain": 40.0},
    "PantographForce": {"T_f": 5.0, "k_c3": 1e6, "alpha": 0.05},
    "TwoMassForce": {"F_f1": 3.0, "F_f2": 2.0, "p_gain": 40.0},
    "ThreeMassForce": {"c2": 37.0, "c3": 11.0, "F_f1": 3.0, "F_f2": 2.0, "F_f3": 1.0,
                       "p_gain": 40.0},
}
#: Inputs at the first point and their shift to the second: (eta m, p bar), (M_b N m, F_c N) or
#: (F_c N, p bar).
INPUT_POINTS = {
    "Pantograph": ([2.0, 4.0], [-0.004, 1.5]),
    "TwoMass": ([0.0, 3.0], [-0.004, 1.5]),
    "ThreeMass": ([0.0, 3.0], [-0.004, 1.5]),
    "PantographForce": ([1040.0, 80.0], [15.0, -10.0]),
    "TwoMassForce": ([120.0, 3.0], [-10.0, 1.5]),
    "ThreeMassForce": ([120.0, 3.0], [-10.0, 1.5]),
}


@pytest.fixture(scope="module")
def project_fmus(project_fmus, force_fmus):
    """Every FMU of ``panto build-fmu``: the session's displacement- and force-excited ones."""
    return {**project_fmus, **force_fmus}


class MeProbe:
    """An ME instance in continuous-time mode whose states and inputs can be set at will."""

    def __init__(self, path, unzipdir: str, parameters: dict):
        self.md = read_model_description(str(path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = instantiate_fmu(unzipdir, self.md, "ModelExchange")
        self.nx = self.md.numberOfContinuousStates
        self.inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output"]
        if not self.fmi3:
            self.fmu.setupExperiment(startTime=0.0)
        self._set_real(parameters)
        if self.fmi3:
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.fmu.updateDiscreteStates() if self.fmi3 else self.fmu.newDiscreteStates()
        self.fmu.enterContinuousTimeMode()

    def _set_real(self, values: dict) -> None:
        refs = [self.vr[name] for name in values]
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(refs, list(values.values()))

    def states(self) -> np.ndarray:
        x = (ctypes.c_double * self.nx)()
        self.fmu.getContinuousStates(x, self.nx)
        return np.array(x)

    def evaluate(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """[dx/dt; y] at states x and inputs u."""
        self.fmu.setContinuousStates((ctypes.c_double * self.nx)(*x), self.nx)
        self._set_real(dict(zip(self.inputs, u)))
        dx = (ctypes.c_double * self.nx)()
        (self.fmu.getContinuousStateDerivatives if self.fmi3 else self.fmu.getDerivatives)(dx, self.nx)
        refs = [self.vr[name] for name in self.outputs]
        y = (self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)(refs)
        return np.concatenate([np.array(dx), np.array(y)])

    def difference_quotients(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Forward differences of [dx/dt; y] with respect to [x; u] (columns)."""
        point = np.concatenate([x, u])
        base = self.evaluate(x, u)
        columns = []
        for k in range(point.size):
            step = 1e-6 * (1.0 + abs(point[k]))
            shifted = point.copy()
            shifted[k] += step
            columns.append((self.evaluate(shifted[:self.nx], shifted[self.nx:]) - base) / step)
        return np.array(columns).T

    def declared(self) -> tuple[np.ndarray, np.ndarray]:
        """The declared structure: a Boolean matrix and the matrix of dependency kinds."""
        unknowns = ([u.variable.name for u in self.md.derivatives]
                    + [u.variable.name for u in self.md.outputs])
        knowns = [v.name for v in self.md.modelVariables if v.initial == "approx"] + self.inputs
        kinds = np.full((len(unknowns), len(knowns)), "", dtype=object)
        for unknown in self.md.derivatives + self.md.outputs:
            row = unknowns.index(unknown.variable.name)
            for known, kind in zip(unknown.dependencies, unknown.dependenciesKind):
                kinds[row, knowns.index(known.name)] = kind
        return kinds != "", kinds


@pytest.mark.parametrize("file", FILES)
def test_declared_dependencies_equal_the_jacobian_sparsity(project_fmus, tmp_path, file):
    name = file.removesuffix(".fmu").removesuffix("_fmi3").removesuffix("Linear")
    path = project_fmus[file].path
    probe = MeProbe(path, extract(str(path), str(tmp_path)), GENERIC_PARAMETERS[name])
    x0 = probe.states()
    u0, shift = (np.array(values) for values in INPUT_POINTS[name])
    rng = np.random.default_rng(7)
    scale = np.concatenate([np.full(probe.nx // 2, 1e-3), np.full(probe.nx // 2, 0.05)])
    first = x0 + scale * rng.uniform(0.5, 1.0, probe.nx)
    second = x0 + scale * rng.uniform(-2.0, -1.0, probe.nx)
    jacobian = probe.difference_quotients(first, u0)
    other = probe.difference_quotients(second, u0 + shift)
    declared, kinds = probe.declared()
    assert declared.shape == jacobian.shape
    np.testing.assert_array_equal(jacobian != 0.0, declared)
    linear = (kinds == "constant") | (kinds == "tunable")
    np.testing.assert_allclose(other[linear], jacobian[linear], rtol=1e-4,
                               atol=1e-6 * np.max(np.abs(jacobian)))
    probe.fmu.terminate()
    probe.fmu.freeInstance()


@pytest.mark.parametrize("file", ["Pantograph.fmu", "Pantograph_fmi3.fmu", "TwoMass.fmu"])
def test_positions_have_no_direct_feedthrough_from_the_inputs(project_fmus, file):
    """y_cb and xi are functions of the states only: no algebraic loop with a catenary."""
    md = read_model_description(str(project_fmus[file].path))
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    for output in md.outputs:
        feedthrough = {v.name for v in output.dependencies} & inputs
        assert feedthrough == ({"eta"} if output.variable.name == "F_c" else set()), output.variable.name


def _reference_events(model: Model, x0: np.ndarray, stop: float) -> np.ndarray:
    """Contact gap zero crossings of the Python twin (eta = 0), by scipy's root finding."""
    head = len(model.state_names) // 2 - 1
    solution = solve_ivp(lambda _, x: model.derivatives(x, 0.0, 0.0), (0.0, stop), x0,
                         method="DOP853", rtol=1e-12, atol=1e-14, max_step=1e-3,
                         events=lambda _, x: x[head])
    return solution.t_events[0]


@pytest.mark.parametrize("file", ["TwoMass.fmu", "ThreeMass_fmi3.fmu"])
def test_model_exchange_locates_contact_loss_and_recontact(project_fmus, file):
    """Released from equilibrium with the head thrown down at 0.5 m/s, it leaves the (fixed)
    wire and bounces back; the wire stands still so that fmpy's held inputs play no part."""
    name = file.removesuffix(".fmu").removesuffix("_fmi3")
    stop, interval = 0.6, 1e-3
    model = Model(name, {"unilateral_contact": 1.0})
    x0 = model.equilibrium(eta=0.0, p=0.0)
    x0[-1] = -0.5  # head velocity [m/s]
    states = dict(zip(model.state_names, x0))
    result = simulate_fmu(str(project_fmus[file].path), fmi_type="ModelExchange",
                          start_values={"unilateral_contact": True, "start_in_equilibrium": False,
                                        **states},
                          output=["xi", "F_c"], relative_tolerance=1e-10,
                          output_interval=interval, stop_time=stop)
    times = result["time"]
    events = np.unique(times[1:][np.diff(times) == 0.0])  # fmpy records each event twice
    reference = _reference_events(model, x0, stop)
    assert len(reference) >= 2  # loss and re-contact really happen
    assert np.all(result["F_c"] >= 0.0)  # the contact only pushes
    assert len(events) == len(reference), (events, reference)
    np.testing.assert_allclose(events, reference, atol=1e-2 * interval)
