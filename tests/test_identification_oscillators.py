"""Oscillator structures (thesis 2.6, 2.7, 4.6, 4.7): simulation against the symbolic model
integrated by solve_ivp, and recovery of known parameters from noisy self-simulated data."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from panto.fmu_src.models import Model
from panto.identification.estimation.base import IdentificationData, IdentificationError
from panto.identification.structures.registry import identifier
from panto.identification.structures import friction_kernel
from panto.identification.structures.oscillators import OscillatorStructure, coulomb_flow, identify_oscillator

PERIOD = 0.02  # 50 Hz, the identification rate (thesis 4.2)


def aprbs(rng, n, low, high, hold_min, hold_max):
    """Amplitude-modulated pseudo-random steps, smoothed over two samples."""
    values, k = np.empty(n), 0
    while k < n:
        hold = rng.integers(hold_min, hold_max)
        values[k:k + hold] = rng.uniform(low, high)
        k += hold
    return np.convolve(values, np.ones(3) / 3, mode="same")


def make_inputs(seed=0, seconds=40.0):
    rng = np.random.default_rng(seed)
    n = int(seconds / PERIOD)
    t = np.arange(n) * PERIOD
    eta = aprbs(rng, n, 1.95, 2.05, 10, 60)
    p = aprbs(rng, n, 3.5, 4.5, 25, 150)
    eta[:5], p[:5] = eta[5], p[5]
    return t, eta, p


def data_for(t, eta, p, outputs, names):
    return IdentificationData(t, np.column_stack([eta, p]), outputs, ("eta", "p"), names,
                              source="test")


def true_parameters(masses, friction):
    s = OscillatorStructure(masses, friction)
    values = s.nominal()
    # dampers raised from the EN 50318 values: the head mode on k_E then has about 13 % damping
    # (with c2 = 10 N s/m it has 0.8 %: the fit needs about three times the evaluations and
    # some starts end in a local minimum of the output error)
    values.update(p_gain=130.0, F_0=-420.0, y_0=1.93, c2=150.0)
    if masses == 3:
        values.update(c3=150.0)
    if friction:
        values.update({f"F_f{i + 1}": 6.0 for i in range(masses)}, v_eps=1e-3)
    return values


def reference_outputs(masses, parameters, t, eta, p):
    """The fmu_src symbolic model (sympy -> lambdify) integrated by DOP853, inputs linear."""
    structure = OscillatorStructure(masses, "F_f1" in parameters)
    model = Model(structure.model_name, structure.fmu_parameters(parameters))
    x0 = model.equilibrium(eta[0], p[0])
    sol = solve_ivp(lambda tt, x: model.derivatives(x, np.interp(tt, t, eta), np.interp(tt, t, p)),
                    (t[0], t[-1]), x0, t_eval=t, method="DOP853", rtol=1e-9, atol=1e-11,
                    max_step=PERIOD / 2)
    return np.array([model.outputs(sol.y[:, k], eta[k], p[k]) for k in range(len(t))])


@pytest.mark.parametrize("masses", [2, 3])
def test_linear_discretisation_matches_symbolic_model(masses):
    t, eta, p = make_inputs(1, 10.0)
    params = true_parameters(masses, False)
    structure = OscillatorStructure(masses, False, outputs=("y_cb", "xi", "F_c"))
    y = structure.simulate(params, data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c")))
    ref = reference_outputs(masses, params, t, eta, p)
    error = np.abs(y - ref).max(axis=0) / np.ptp(ref, axis=0)
    assert np.all(error < 1e-5), error


def test_zero_order_hold_matches_held_inputs():
    t, eta, p = make_inputs(2, 4.0)
    params = true_parameters(2, False)
    structure = OscillatorStructure(2, False, outputs=("y_cb", "xi", "F_c"), hold="zoh")
    y = structure.simulate(params, data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c")))
    model = Model("TwoMass", structure.fmu_parameters(params))
    x, rows = model.equilibrium(eta[0], p[0]), [model.outputs(model.equilibrium(eta[0], p[0]), eta[0], p[0])]
    for k in range(len(t) - 1):
        x = solve_ivp(lambda tt, s: model.derivatives(s, eta[k], p[k]), (0, PERIOD), x,
                      rtol=1e-10, atol=1e-12).y[:, -1]
        rows.append(model.outputs(x, eta[k + 1], p[k + 1]))
    ref = np.array(rows)
    assert np.all(np.abs(y - ref).max(axis=0) / np.ptp(ref, axis=0) < 1e-5)


@pytest.mark.parametrize("masses", [2, 3])
def test_friction_integrator_matches_symbolic_model(masses):
    t, eta, p = make_inputs(3, 8.0)
    params = true_parameters(masses, True)
    structure = OscillatorStructure(masses, True, outputs=("y_cb", "xi", "F_c"))
    y = structure.simulate(params, data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c")))
    ref = reference_outputs(masses, params, t, eta, p)
    error = np.abs(y - ref).max(axis=0) / np.ptp(ref, axis=0)
    assert np.all(error < 0.01), error
    # friction matters on these inputs: the frictionless model differs by far more
    linear = OscillatorStructure(masses, False, outputs=("y_cb", "xi", "F_c"))
    y_lin = linear.simulate({k: v for k, v in params.items() if k in linear.parameter_names},
                            data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c")))
    assert np.abs(y_lin - ref).max(axis=0)[2] > 5 * np.abs(y - ref).max(axis=0)[2]


def test_coulomb_flow_is_exact():
    v_eps, rate = 1e-3, 3.0  # F_f / m [m/s^2]
    v0 = np.array([-2.0, -0.01, -1e-4, 0.0, 3e-4, 0.05, 5.0])
    sol = solve_ivp(lambda t, v: -rate * np.tanh(v / v_eps), (0, 0.01), v0, method="Radau",
                    rtol=1e-10, atol=1e-13)
    exact = coulomb_flow(v0, np.full(v0.shape, rate * 0.01 / v_eps), v_eps)
    np.testing.assert_allclose(exact, sol.y[:, -1], rtol=1e-6, atol=1e-10)


def test_an_overwhelming_friction_stops_the_masses_without_a_warning():
    """A friction so far above ``v_eps / h`` that the half step's decay factor underflows to 0:
    the flow over an infinite decay stops every velocity below ``700 v_eps`` (where it is
    exact), and the simulation runs on without a divide-by-zero warning (seen in every run of
    the diagnosis families) and stays finite."""
    import warnings

    v_eps = 1e-3
    stopped = coulomb_flow(np.array([-0.5, -1e-4, 0.0, 3e-4, 0.5]), np.full(5, np.inf), v_eps)
    np.testing.assert_allclose(stopped, 0.0, atol=1e-15)
    t, eta, p = make_inputs(4, 2.0)
    params = true_parameters(2, True)
    params.update(F_f1=1e9, F_f2=1e9, v_eps=1e-6)
    structure = OscillatorStructure(2, True, outputs=("y_cb", "xi", "F_c"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        y = structure.simulate(params, data_for(t, eta, p, np.zeros((len(t), 3)),
                                                ("y_cb", "xi", "F_c")))
    assert np.all(np.isfinite(y))


def _friction_runs(masses, monkeypatch, switches=("1", "0")):
    """Outputs of the friction structure on stick-slip inputs, once per kernel switch."""
    t, eta, p = (v[:-2] for v in make_inputs(4, 6.0))  # without the smoothing's end effect
    params = true_parameters(masses, True)
    params.update({f"F_f{i + 1}": 25.0 for i in range(masses)})  # the masses stick for a while
    structure = OscillatorStructure(masses, True, outputs=("y_cb", "xi", "F_c"))
    data = data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c"))
    runs = []
    for switch in switches:
        monkeypatch.setenv(friction_kernel.SWITCH_VARIABLE, switch)
        runs.append(structure.simulate(params, data))
    return runs


@pytest.mark.parametrize("masses", [2, 3])
def test_compiled_friction_loop_equals_the_python_loop(masses, monkeypatch):
    """The C kernel and the Python reference loop give the same outputs to round-off, on a
    record where the velocities cross zero and the masses stick (v within v_eps)."""
    if friction_kernel.load_library() is None:
        pytest.skip("no C compiler: the compiled friction kernel is not available")
    compiled, python = _friction_runs(masses, monkeypatch)
    error = np.abs(compiled - python).max(axis=0) / np.ptp(python, axis=0)
    assert np.all(error < 1e-12), error
    # the stick phases are there: the run without friction differs by far more than round-off
    t, eta, p = (v[:-2] for v in make_inputs(4, 6.0))
    linear = OscillatorStructure(masses, False, outputs=("y_cb", "xi", "F_c"))
    y_lin = linear.simulate({k: v for k, v in true_parameters(masses, False).items()},
                            data_for(t, eta, p, np.zeros((len(t), 3)), ("y_cb", "xi", "F_c")))
    assert np.abs(y_lin - python).max(axis=0)[2] > 0.05 * np.ptp(python[:, 2])


def test_compiled_friction_flow_over_its_whole_range():
    """One sub-step with Phi = I and no drive is the friction flow alone: the kernel's closed form
    against the Python loop's (and coulomb_flow) from rest to the clip at 700 v_eps and from no
    friction (q = 1) to a mass stopped within the sub-step (q = 0, tiny q)."""
    if friction_kernel.load_library() is None:
        pytest.skip("no C compiler: the compiled friction kernel is not available")
    v_eps = 1e-3
    speeds = v_eps * np.array([0.0, 1e-9, 1e-3, 0.3, 1.0, 5.0, 19.99, 20.01, 35.0, 300.0, 700.0,
                               2000.0])
    for q in (1.0, 0.999, 0.5, 1e-5, 1e-12, 1e-250, 0.0):
        for sign in (1.0, -1.0):
            for v in sign * speeds:
                got = {}
                for compiled in (True, False):
                    states, x = np.zeros((2, 2)), np.array([0.1, v])
                    friction_kernel.run(np.eye(2), np.zeros((1, 2)), x, 1, np.array([q]),
                                        np.array([q * q]), v_eps, states, compiled=compiled)
                    got[compiled] = (states[1, 1], x[1])
                with np.errstate(divide="ignore"):  # q = 0: an infinite decay
                    exact = coulomb_flow(np.array([v, v]), -np.log([q, q * q]), v_eps)
                for value, reference in zip(got[True], exact):
                    assert np.isfinite(value) and abs(value - reference) <= \
                        1e-12 * max(abs(v), abs(reference), v_eps), (q, v, value, reference)
                np.testing.assert_allclose(got[True], got[False], rtol=0,
                                           atol=1e-12 * max(abs(v), v_eps))


def test_friction_kernel_paths_and_fallback_without_compiler(tmp_path, monkeypatch):
    """The dispatcher names the path it took; without a C compiler the kernel is not built and
    the structure runs the Python loop (same outputs as the switched-off kernel)."""
    n, substeps = 2, 4
    rng = np.random.default_rng(0)
    phi = np.eye(2 * n) + 0.01 * rng.standard_normal((2 * n, 2 * n))
    drive = 1e-3 * rng.standard_normal((3 * substeps, 2 * n))
    half, full = np.array([0.9, 0.8]), np.array([0.81, 0.64])
    outs = {}
    for compiled in (True, False):
        if compiled and friction_kernel.load_library() is None:
            continue
        states, x = np.zeros((4, 2 * n)), np.full(2 * n, 1e-3)
        path = friction_kernel.run(phi, drive, x, substeps, half, full, 1e-3, states,
                                   compiled=compiled)
        assert path == ("compiled" if compiled else "python")
        outs[path] = states
    if "compiled" in outs:
        np.testing.assert_allclose(outs["compiled"], outs["python"], rtol=1e-13, atol=1e-18)
    (reference,) = _friction_runs(2, monkeypatch, switches=("0",))
    monkeypatch.setattr(friction_kernel, "_compiler", lambda: None)
    monkeypatch.setenv(friction_kernel.CACHE_VARIABLE, str(tmp_path))
    friction_kernel.load_library.cache_clear()
    try:
        assert friction_kernel.load_library() is None and not friction_kernel.available()
        (fallback,) = _friction_runs(2, monkeypatch, switches=("1",))
    finally:
        friction_kernel.load_library.cache_clear()
    np.testing.assert_array_equal(fallback, reference)


def test_invalid_parameters_raise():
    t, eta, p = make_inputs(0, 2.0)
    data = data_for(t, eta, p, np.zeros((len(t), 2)), ("F_c", "y_cb"))
    with pytest.raises(IdentificationError, match="m1"):
        OscillatorStructure(2).simulate({"m1": -1.0}, data)
    with pytest.raises(IdentificationError, match="unknown"):
        OscillatorStructure(2).simulate({"m9": 1.0}, data)


@pytest.mark.parametrize("masses", [2, 3])
def test_recovers_parameters_within_confidence_intervals(masses):
    rng = np.random.default_rng(10 + masses)
    t, eta, p = make_inputs(masses, 40.0)
    truth = true_parameters(masses, False)
    structure = OscillatorStructure(masses, False)
    clean = structure.simulate(truth, data_for(t, eta, p, np.zeros((len(t), 2)), ("F_c", "y_cb")))
    noise_std = 0.01 * np.std(clean, axis=0)
    noisy = clean + noise_std * rng.standard_normal(clean.shape)
    data = data_for(t, eta, p, noisy, ("F_c", "y_cb"))
    factors = np.exp(rng.uniform(-0.2, 0.2, 3 * masses))  # start 20 % off the truth
    names = [f"{s}{i + 1}" for s in "mkc" for i in range(masses)]
    start = {n: truth[n] * f for n, f in zip(names, factors)}
    result = identifier({2: "two-mass", 3: "three-mass"}[masses]).identify(
        data, initial=start, fixed={"y_0": truth["y_0"]})
    assert result.success, result.message
    assert set(result.free) == set(names) | {"p_gain", "F_0", "y_cb_offset"}
    for name in result.free:
        # within the 95 % interval, with slack to 3.5 sigma for the 9-12 parameters tested at once
        sigma = result.std[name]
        assert 0 < sigma < 0.2 * max(abs(truth[name]), 1e-3), (name, sigma)
        assert abs(result.parameters[name] - truth[name]) < 3.5 * sigma, \
            (name, result.parameters[name], truth[name], sigma)
    floor = 100 * (1 - noise_std / np.std(clean, axis=0))
    for j, name in enumerate(("F_c", "y_cb")):
        assert result.fit[name] > floor[j] - 0.5


def test_friction_structure_recovers_friction():
    rng = np.random.default_rng(7)
    t, eta, p = make_inputs(5, 12.0)
    truth = true_parameters(2, True)
    structure = OscillatorStructure(2, True)
    clean = structure.simulate(truth, data_for(t, eta, p, np.zeros((len(t), 2)), ("F_c", "y_cb")))
    noise_std = 0.01 * np.std(clean, axis=0)
    data = data_for(t, eta, p, clean + noise_std * rng.standard_normal(clean.shape), ("F_c", "y_cb"))
    free = ("F_f1", "F_f2", "c1", "c2", "p_gain", "F_0", "y_cb_offset")
    result = identify_oscillator(data, masses=2, friction=True, free=free, fixed={"y_0": truth["y_0"]},
                                 initial={"F_f1": 2.0, "F_f2": 2.0, "c1": 120.0, "c2": 120.0})
    assert result.success, result.message
    for name in free:
        assert abs(result.parameters[name] - truth[name]) < 3.5 * result.std[name], name


def test_identifiers_registered():
    for name in ("two-mass", "two-mass-friction", "three-mass", "three-mass-friction"):
        assert identifier(name).in_comparison
