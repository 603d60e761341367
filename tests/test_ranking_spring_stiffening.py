"""A hardening spring of an oscillator in the diagnosis' ranking (identification/diagnosis/
ranking.py ``spring_stiffening``): the regressor is the cube of the nominal's own simulated
deflection of each chain spring, passed through the response of the nominal's dynamics to that
spring's force. With the contact force as the only output the measured "position" is the wire
height ``eta``, whose cube does not follow the spring: a cubic base spring ranked below five other
candidates and was never refitted (tuning split, three-mass cubic_stiffness/77: ``unexplained``)."""
from __future__ import annotations

import numpy as np
from scipy import integrate
from scipy import signal as sps

from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.ranking import rank_candidates, spring_stiffening
from panto.identification.diagnosis.refit import Model
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

CANDIDATES = ["coulomb_friction", "extra_mode", "input_delay", "actuator_lag", "saturation",
              "dead_zone", "cubic_stiffness"]


def _run(seed: int, outputs: tuple[str, ...], n: int = 1500) -> IdentificationData:
    """A 30 s multisine of the wire height and a slowly varying bellow pressure at 50 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 50.0
    eta = 2.0 + sum(0.006 * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
                    for f in (0.3, 0.7, 1.3, 2.9, 4.1))
    p = 4.0 + 0.3 * sps.filtfilt(*sps.butter(2, 0.02), rng.normal(size=n))
    return IdentificationData(t, np.column_stack([eta, p]), np.zeros((n, len(outputs))),
                              ("eta", "p"), outputs)


#: How many times the equivalent pressure change the direct path applies (docstring below).
SCALE = 1e3


def test_the_base_spring_reaches_the_outputs_like_the_equivalent_pressure():
    """Two independent paths: the ranking's response to the base spring's cubic (and square)
    force x (it pulls mass 1 only) against the model run with the pressure lowered by
    x / p_gain (the bellow force p_gain p acts on mass 1); the deflections are the nominal's own
    free run, and every variant carries its first sample's deflections as the centres. The
    model is linear in its inputs, so the direct path runs the pressure lowered by `SCALE` times
    that and divides the difference by `SCALE`: the two runs' difference is then far above their
    rounding (unscaled, 1e-4 N of response against 1e-10 N of rounding, machine-dependent)."""
    outputs = ("F_c", "y_cb", "xi")
    structure = OscillatorStructure(3, outputs=outputs)
    parameters = structure.nominal()
    data = _run(1, outputs)
    regressors, paths = spring_stiffening(Model(structure, parameters, ()), data)
    assert set(regressors) == {"d1^3", "d2^3", "d3^3", "d1^2", "d2^2", "d3^2"}
    states = structure.states(parameters, data)
    centres = (states[0, 0], states[0, 1] - states[0, 0], states[0, 2] - states[0, 1])
    assert all(setting["centres"] == centres for _, setting in regressors.values())
    for power in (3, 2):
        x = regressors[f"d1^{power}"][0]
        assert np.array_equal(x, (states[:, 0] - states[0, 0]) ** power)
        lowered = data.inputs.copy()
        lowered[:, 1] -= SCALE * x / parameters["p_gain"]
        direct = (structure.simulate(parameters, IdentificationData(
            data.time, lowered, data.outputs, data.input_names, outputs)) -
            structure.simulate(parameters, data)) / SCALE
        path = paths[("cubic_stiffness", f"d1^{power}")]
        assert np.max(np.abs(path - direct)) < 1e-6 * np.max(np.abs(direct)) + 1e-12
    spring2 = (states[:, 1] - states[:, 0] - (states[0, 1] - states[0, 0])) ** 3
    assert np.array_equal(regressors["d2^3"][0], spring2)


def _plant_with_a_cubic_base_spring(structure: OscillatorStructure, parameters: dict,
                                    data: IdentificationData, k3: float) -> np.ndarray:
    """The oscillator's linear dynamics plus ``-k3 (z1 - z1(0))^3`` on mass 1, integrated by
    SciPy's adaptive Runge-Kutta (inputs linear between samples): written apart from the
    product's nonlinear oscillator."""
    a, b, c, d = structure.matrices(parameters)
    u = np.column_stack([data.inputs, np.ones(len(data))])
    x0 = structure.equilibrium(parameters, u[0, 0], u[0, 1])
    mass1 = structure.values(parameters)["m1"]
    n = structure.masses

    def rates(t, x):
        now = np.array([np.interp(t, data.time, column) for column in u.T])
        dx = a @ x + b @ now
        dx[n] -= k3 * (x[0] - x0[0]) ** 3 / mass1
        return dx

    run = integrate.solve_ivp(rates, (data.time[0], data.time[-1]), x0, t_eval=data.time,
                              method="LSODA", rtol=1e-9, atol=1e-12, max_step=data.sample_period)
    rows = [("y_cb", "xi", "F_c").index(o) for o in data.output_names]
    return (run.y.T @ c[rows].T + u @ d[rows].T)


def test_a_cubic_base_spring_seen_only_in_the_contact_force_ranks_first():
    """Data of a three-mass oscillator whose base spring hardens (its cubic force 60 % of the
    spring's linear force at the run's largest swing, a few per cent at its typical one), measured only through the contact force (noise
    0.2 N): against the linear nominal at the true parameters, cubic_stiffness leads the ranking
    through the base spring's deflection, far ahead of the wire height's cube."""
    outputs = ("F_c",)
    structure = OscillatorStructure(3, outputs=outputs)
    truth = structure.nominal()
    data = _run(2, outputs)
    deflection = structure.states(truth, data)[:, 0]
    swing = np.max(np.abs(deflection - deflection[0]))
    k1 = structure.values(truth)["k1"]
    k3 = 0.6 * k1 / swing ** 2  # the cubic force 60 % of the linear one at the largest swing
    clean = _plant_with_a_cubic_base_spring(structure, truth, data, k3)
    linear = structure.simulate(truth, data)
    assert np.std(clean - linear) > 5 * 0.2, "the hardening must show above the noise"
    measured = IdentificationData(data.time, data.inputs, clean + np.random.default_rng(3).normal(
        scale=0.2, size=clean.shape), data.input_names, outputs)
    roles = SignalRoles(position="eta", force=None, actuators=("eta", "p"),
                        sensor_position=None, head_position=None)
    ranking = rank_candidates(Model(structure, truth, ("F_0", "p_gain")), measured, roles,
                              CANDIDATES, 5)
    top = ranking["top"][0]
    assert top["effect"] == "cubic_stiffness", [(c["effect"], c["err"]) for c in ranking["top"]]
    assert top["variant"] == "d1^3", top["variant"]
    assert top["err"] > 0.3, top["err"]
