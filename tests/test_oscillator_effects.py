"""Oscillators with friction and cubic springs inside their dynamics (the diagnosis' inside form
of ``coulomb_friction`` and ``cubic_stiffness`` for the two- and three-mass nominals)."""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.diagnosis.augmentations import AugmentedStructure
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures import oscillator_effects
from panto.identification.structures.oscillator_effects import NonlinearOscillator
from panto.identification.structures.oscillators import OscillatorStructure

OUTPUTS = ("F_c", "y_cb")


def _data(duration: float = 20.0, rate: float = 100.0, seed: int = 0) -> IdentificationData:
    t = np.arange(0.0, duration, 1.0 / rate)
    rng = np.random.default_rng(seed)
    levels = rng.uniform(-1.0, 1.0, size=int(duration) + 1)
    eta = 2.0 + 0.01 * np.sin(2 * np.pi * 1.3 * t) + 0.004 * levels[t.astype(int)]
    p = 4.5 + 0.3 * np.sin(2 * np.pi * 0.4 * t)
    return IdentificationData(t, np.column_stack([eta, p]), np.zeros((len(t), 2)), ("eta", "p"),
                              OUTPUTS, {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m"}, "test")


@pytest.mark.parametrize("masses", [2, 3])
def test_without_nonlinear_forces_it_is_the_linear_oscillator(masses):
    """Zero friction and a vanishing cubic term (which forces the splitting loop) reproduce the
    exact discretisation of the linear oscillator: two independent integrations agree."""
    data = _data(8.0)
    linear = OscillatorStructure(masses, outputs=OUTPUTS)
    both = NonlinearOscillator(masses, friction=True, cubic=True, outputs=OUTPUTS)
    reference = linear.simulate(linear.nominal(), data)
    looped = both.simulate({**linear.nominal(), "kc1": 1e-300}, data)
    scale = np.std(reference, axis=0)
    assert np.max(np.abs(looped - reference) / scale) < 1e-9


def test_splitting_loop_agrees_with_the_friction_oscillator():
    """Friction alone: the oscillators' own friction integration and this module's splitting
    loop (forced by a vanishing cubic term) give the same run."""
    data = _data(8.0)
    friction = NonlinearOscillator(2, friction=True, outputs=OUTPUTS)
    both = NonlinearOscillator(2, friction=True, cubic=True, outputs=OUTPUTS)
    values = {**friction.nominal(), "F_f1": 6.0, "F_f2": 1.0}
    a = friction.simulate(values, data)
    b = both.simulate({**values, "kc2": 1e-300}, data)
    linear = OscillatorStructure(2, outputs=OUTPUTS).simulate(OscillatorStructure(2).nominal(),
                                                              data)
    assert np.max(np.abs(a - linear), axis=0)[1] > 1e-4  # the friction changes the run
    assert np.max(np.abs(a - b) / np.std(a, axis=0)) < 1e-7


def _static_residual(substep: float, monkeypatch) -> tuple[float, float, float]:
    """Relative acceleration left at rest after a pressure step (nonlinear static balance),
    and the cross bar's shift from the linear model's equilibrium [m] and the step's [m]."""
    monkeypatch.setattr(oscillator_effects, "MAX_SUBSTEP", substep)
    t = np.arange(0.0, 30.0, 0.02)
    p = np.where(t < 1.0, 4.5, 5.5)
    data = IdentificationData(t, np.column_stack([np.full_like(t, 2.0), p]),
                              np.zeros((len(t), 2)), ("eta", "p"), OUTPUTS, {}, "step")
    structure = NonlinearOscillator(2, cubic=True, outputs=("y_cb", "xi"))
    values = {**structure.nominal(), "kc1": 2e3, "kc2": 5e4, "c1": 60.0, "c2": 300.0}
    y = structure.simulate(values, data)
    a, b, _, _ = structure.matrices(values)
    start = structure.equilibrium(values, 2.0, 4.5)
    end = structure.equilibrium(values, 2.0, 5.5)  # the linear model's
    z = y[-1] - values["y_0"]  # y_cb, xi: the two masses
    d = np.diff(z, prepend=0.0) - np.diff(start[:2], prepend=0.0)
    tension = np.array([values["k1"] * values["kc1"], values["k2"] * values["kc2"]]) * d ** 3
    cubic = np.array([-tension[0] + tension[1], -tension[1]])
    x = np.concatenate([z, [0.0, 0.0]])
    linear = (a @ x + b @ np.array([2.0, 5.5, 1.0]))[2:]
    residual = linear + cubic / np.array([values["m1"], values["m2"]])
    return (float(np.max(np.abs(residual)) / np.max(np.abs(linear))), float(z[0] - end[0]),
            float(end[0] - start[0]))


def test_cubic_spring_settles_where_the_nonlinear_static_balance_holds(monkeypatch):
    """After a pressure step the state comes to rest where the linear forces and the cubic spring
    forces balance, away from the linear model's equilibrium; the splitting's error of that
    balance falls as the square of the sub-step (second order)."""
    coarse, shift, step = _static_residual(2.5e-3, monkeypatch)
    fine, _, _ = _static_residual(2.5e-3 / 4, monkeypatch)
    assert coarse < 1e-2
    assert fine < coarse / 10.0
    assert abs(shift) > 0.05 * abs(step)  # the hardening shows


def test_refit_recovers_a_planted_friction_force():
    """Data from the friction oscillator (5 N on the lower mass), the nominal refitted with the
    friction inside as the diagnosis does (every mass gets its force, all start at zero): the
    force lands on the lower mass near 5 N and the other near zero."""
    data = _data(20.0, seed=1)
    truth = NonlinearOscillator(2, friction=True, outputs=OUTPUTS)
    values = {**truth.nominal(), "F_f1": 5.0}
    clean = truth.simulate(values, data)
    rng = np.random.default_rng(2)
    noisy = clean + 0.002 * np.std(clean, axis=0) * rng.standard_normal(clean.shape)
    data = IdentificationData(data.time, data.inputs, noisy, data.input_names, OUTPUTS,
                              data.units, "planted friction")
    nominal = OscillatorStructure(2, outputs=OUTPUTS)
    augmented = AugmentedStructure(nominal, "coulomb_friction", SignalRoles(), {})
    assert augmented.mode == "inside" and augmented.effect_parameters == ("F_f1", "F_f2")
    assert augmented.magnitude_parameters == ("F_f1", "F_f2")
    free = ("k1", "c1", "p_gain", "F_0", "F_f1", "F_f2")
    start = {k: v for k, v in nominal.nominal().items() if k in augmented.parameter_names}
    result = fit_least_squares(augmented, data, free=free, initial=start, max_evaluations=400)
    assert result.parameters["F_f1"] == pytest.approx(5.0, rel=0.1)
    assert result.parameters["F_f2"] < 0.5


def test_effects_without_an_inside_form_are_refused():
    with pytest.raises(IdentificationError, match="no inside form"):
        oscillator_effects.oscillator_with_effect(OscillatorStructure(2), "offset", {})
    with pytest.raises(IdentificationError, match="friction, cubic"):
        NonlinearOscillator(2)


@pytest.mark.skipif(not oscillator_effects.friction_kernel.available(),
                    reason="no C compiler for the kernel")
def test_compiled_loop_agrees_with_the_python_reference():
    """Quadratic and cubic springs and friction together, the springs' centres away from the
    start (their tension not zero there): the C kernel and the Python loop give the same states
    to round-off (a stiff, sticking case: 2 mm/s smoothing, 20 N on the frame)."""
    structure = NonlinearOscillator(3, friction=True, cubic=True, outputs=OUTPUTS)
    values = {**structure.nominal(), "kc1": 3e3, "kc2": -2e3, "kc3": 5e4, "kq1": 40.0,
              "kq3": -300.0, "F_f1": 20.0, "F_f3": 2.0}
    data = _data(6.0)
    v = structure.values(values)
    a, b, _, _ = structure.matrices(values)
    u = np.column_stack([data.input("eta"), data.input("p"), np.ones(len(data))])
    x0 = structure.equilibrium(values, u[0, 0], u[0, 1])
    mass = np.array([v[f"m{i}"] for i in (1, 2, 3)])
    springs = np.array([v[f"k{i}"] * v[f"kc{i}"] for i in (1, 2, 3)])
    quadratic = np.array([v[f"k{i}"] * v[f"kq{i}"] for i in (1, 2, 3)])
    friction = np.array([v[f"F_f{i}"] for i in (1, 2, 3)]) / mass
    centre = np.diff(x0[:3], prepend=0.0) + np.array([2e-3, -1e-3, 5e-4])  # tension at start
    runs = [oscillator_effects._simulate_nonlinear(a, b, u, x0, data.sample_period, 4, "foh",
                                                   friction, structure.v_eps, springs, mass,
                                                   compiled=flag, quadratic=quadratic,
                                                   centre=centre)
            for flag in (True, False)]
    scale = np.maximum(np.std(runs[1], axis=0), 1e-12)
    assert np.max(np.abs(runs[0] - runs[1]) / scale) < 1e-9
    assert np.ptp(runs[1][:, 3]) > 0.0  # the frame moves (the comparison is not of rest states)


def test_a_preloaded_spring_hardening_about_its_free_length_is_the_quadratic_and_cubic_terms():
    """A base spring ``k (d + d^3 / L^2)`` about its free length, preloaded to ``d0`` by the
    static force: about the operating point it is ``k' e + 3 k d0 / L^2 e^2 + k / L^2 e^3``
    (``k' = k (1 + 3 d0^2 / L^2)``) with the static force shifted by ``2 k d0^3 / L^2``. The
    plant integrated by SciPy's LSODA and the nonlinear oscillator with those terms agree; the
    cubic term alone (what the structure had before the quadratic term) does not."""
    from scipy import integrate, optimize

    data = _data(10.0, seed=3)
    structure = NonlinearOscillator(2, cubic=True, outputs=OUTPUTS)
    linear = OscillatorStructure(2, outputs=OUTPUTS)
    plant = {**linear.nominal(), "c1": 80.0}
    v = linear.values(plant)
    a, b, c, d = linear.matrices(plant)
    u = np.column_stack([data.inputs, np.ones(len(data))])
    x0 = linear.equilibrium(plant, u[0, 0], u[0, 1])
    d0 = x0[0]  # the base spring's static deflection from its free length (states: from y_0)
    assert abs(d0) > 0.01
    hardening = 0.5 / d0 ** 2  # 1/L^2: the cubic force half the linear one at the preload
    k1 = v["k1"]

    def rates(t, x):
        now = np.array([np.interp(t, data.time, column) for column in u.T])
        dx = a @ x + b @ now
        dx[2] -= k1 * hardening * x[0] ** 3 / v["m1"]
        return dx

    start = optimize.fsolve(lambda x: rates(0.0, x), x0)
    run = integrate.solve_ivp(rates, (data.time[0], data.time[-1]), start, t_eval=data.time,
                              method="LSODA", rtol=1e-10, atol=1e-13,
                              max_step=data.sample_period)
    rows = [("y_cb", "xi", "F_c").index(o) for o in OUTPUTS]
    truth = run.y.T @ c[rows].T + u @ d[rows].T
    e0 = start[0]
    stiff = k1 * (1 + 3 * hardening * e0 ** 2)
    model = {**plant, "k1": stiff, "kq1": 3 * k1 * hardening * e0 / stiff,
             "kc1": k1 * hardening / stiff, "F_0": plant["F_0"] + 2 * k1 * hardening * e0 ** 3}
    simulated = structure.simulate(model, data)
    cubic_only = structure.simulate({**model, "kq1": 0.0}, data)
    scale = np.std(truth, axis=0)
    error = np.max(np.abs(simulated - truth) / scale)
    assert error < 1e-4  # the splitting's second-order error at 2.5 ms sub-steps
    assert np.max(np.abs(cubic_only - truth) / scale) > 100 * error
