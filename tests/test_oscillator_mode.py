"""An extra mass hung on an oscillator's head (identification/structures/oscillator_mode.py), the
diagnosis' ``extra_mode`` inside the dynamics, refitted beside the additive mode
(ranking.py ``_candidate``'s ``other_placement``)."""
from __future__ import annotations

import numpy as np

from fixtures.excitations import load_benchmark

from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillator_mode import OscillatorWithMode
from panto.identification.structures.oscillators import OscillatorStructure

MODE = {"m_e": 0.8, "f_e": 7.0, "zeta_e": 0.04}


def _data(n: int = 10) -> IdentificationData:
    t = np.arange(n) * 0.01
    return IdentificationData(t, np.column_stack([np.full(n, 2.05), np.full(n, 4.0)]),
                              np.zeros((n, 1)), ("eta", "p"), ("F_c",))


def _by_hand(v: dict, masses: int, attached: int, s: complex) -> complex:
    """``F_c / eta`` of the chain (base-1, 1-2, ...) solved at ``s`` with mass `attached`'s mass
    replaced by its dynamic mass ``m_i + m_e (k_e + c_e s) / (m_e s^2 + c_e s + k_e)`` (what a
    mass on a spring and a damper pushes back with)."""
    omega_e = 2 * np.pi * MODE["f_e"]
    k_e, c_e = MODE["m_e"] * omega_e ** 2, 2 * MODE["zeta_e"] * MODE["m_e"] * omega_e
    mass = np.array([v[f"m{i + 1}"] for i in range(masses)], complex)
    mass[attached - 1] += MODE["m_e"] * (k_e + c_e * s) / (MODE["m_e"] * s ** 2 + c_e * s + k_e)
    dynamic = np.zeros((masses, masses), complex)
    for i in range(masses):  # spring and damper i join mass i to mass i-1 (or the base)
        z = v[f"k{i + 1}"] + s * v[f"c{i + 1}"]
        dynamic[i, i] += z
        if i > 0:
            dynamic[i - 1, i - 1] += z
            dynamic[i, i - 1] -= z
            dynamic[i - 1, i] -= z
    dynamic += np.diag(s ** 2 * mass)
    dynamic[-1, -1] += v["k_E"]
    force = np.zeros(masses)
    force[-1] = v["k_E"]
    heights = np.linalg.solve(dynamic, force)
    return v["k_E"] * (heights[-1] - 1.0)


def test_the_contact_force_response_is_the_chain_with_a_dynamic_mass():
    """Two paths to ``F_c / eta``: the structure's state space, and the chain solved by hand at
    each frequency with the carrier's mass replaced by its dynamic mass; they agree, on the head
    of two masses and on the frame of three, and differ from the plain oscillator's near the
    mode."""
    for masses, attached in ((2, 2), (3, 1)):
        structure = OscillatorWithMode(masses, attached=attached, outputs=("F_c",))
        v = {**structure.nominal(), **MODE}
        a, b, c, d = structure.linear_system(v, _data())
        plain = OscillatorStructure(masses, outputs=("F_c",))
        pa, pb, pc, pd = plain.linear_system({k: v[k] for k in plain.parameter_names}, _data())
        worst, mode_effect = 0.0, 0.0
        for frequency in np.geomspace(0.5, 40.0, 60):
            s = 2j * np.pi * frequency
            state_space = (c @ np.linalg.solve(s * np.eye(len(a)) - a, b) + d)[0, 0]
            by_hand = _by_hand(v, masses, attached, s)
            worst = max(worst, abs(state_space - by_hand) / abs(by_hand))
            without = (pc @ np.linalg.solve(s * np.eye(len(pa)) - pa, pb) + pd)[0, 0]
            mode_effect = max(mode_effect, abs(without - by_hand) / abs(by_hand))
        assert worst < 1e-9, (masses, attached, worst)
        assert mode_effect > 0.05, (masses, attached, mode_effect)


def test_units_and_another_effect_keep_the_mass_inside():
    """The structure's units name the mode's parameters; friction added to a model with the mass
    inside goes on from outside, keeping ``m_e``, ``f_e``, ``zeta_e`` (rebuilt inside a friction
    oscillator, which has no such mass, the mode had silently become an additive one); and a
    mass that cannot go inside is an error, never an additive mode in its place."""
    import pytest

    from panto.identification.diagnosis.augmentations import AugmentedStructure
    from panto.identification.diagnosis.effects import SignalRoles
    from panto.identification.estimation.base import IdentificationError
    from panto.identification.structures.oscillator_effects import NonlinearOscillator

    units = OscillatorWithMode(3).units()
    assert (units["m_e"], units["f_e"], units["zeta_e"], units["k2"]) == ("kg", "Hz", "-", "N/m")
    roles = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position="y_cb",
                        head_position=None)
    mode = AugmentedStructure(OscillatorStructure(3, outputs=("F_c", "y_cb")), "extra_mode", roles,
                              {"output": "F_c", "attached": 3, "frequency_hz": 7.0})
    assert mode.mode == "inside" and not mode.supports_inside("coulomb_friction")
    friction = AugmentedStructure(mode, "coulomb_friction", roles, {"output": "F_c"})
    assert {"m_e", "f_e", "zeta_e"} <= set(friction.parameter_names)
    assert not any(n.startswith("extra_mode:") for n in friction.parameter_names)
    with pytest.raises(IdentificationError, match="no extra mass inside"):
        AugmentedStructure(NonlinearOscillator(3, friction=True, outputs=("F_c",)), "extra_mode",
                           roles, {"output": "F_c", "attached": 3})


def test_at_rest_the_extra_mass_changes_no_output():
    """The static state: the extra mass rests where its carrier is, and every output equals the
    plain oscillator's (the mode has no static force)."""
    for masses, attached in ((2, 2), (3, 3), (3, 1)):
        structure = OscillatorWithMode(masses, attached=attached,
                                       outputs=("F_c", "y_cb", "xi"))
        plain = OscillatorStructure(masses, outputs=("F_c", "y_cb", "xi"))
        values = {**structure.nominal(), **MODE}
        rest = structure.equilibrium(values, 2.05, 4.0)
        assert abs(rest[2 * masses] - rest[attached - 1]) < 1e-12 and rest[-1] == 0.0
        data = _data(50)
        data = IdentificationData(data.time, data.inputs, np.zeros((50, 3)), data.input_names,
                                  ("F_c", "y_cb", "xi"))
        own = {k: values[k] for k in plain.parameter_names}
        assert np.allclose(structure.simulate(values, data), plain.simulate(own, data),
                           rtol=1e-12, atol=1e-9)


def _named_at_the_ceiling(seed: int) -> None:
    """Two-mass ``extra_mode`` case `seed` of the benchmark plants, diagnosed with that candidate
    only (a shorter test; the full vocabulary names the same): named, every output at the
    plant's own validation fit (within 0.2 points), the extra mass within 10 %."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "extra_mode", seed, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("extra_mode",), discovery=False,
                                               challenge=False, workers=1))
    assert result.effects == ("extra_mode",), result.summary
    for output, ceiling in case.ceiling.items():
        assert result.fit_after[output] > ceiling - 0.2, (result.fit_after, case.ceiling)
    truth = case.plant.setting["m_e"]
    assert abs(result.final_parameters["m_e"] - truth) < 0.1 * truth, \
        (result.final_parameters["m_e"], truth)


def test_a_strong_mode_on_the_head_is_named_and_closes_the_gap():
    """The seen held-out case two-mass/extra_mode/2017 (benchmarks/effect_plants.py, a plant
    written apart from the diagnosis: 0.77 kg at 7.5 Hz on the 7.2 kg head, multisine at
    50 Hz): the nominal's contact-force fit 16 %, a linear black box's 98 %. The additive mode
    gained 0.4 points and the verdict was ``unexplained``; the mass on the head reaches the
    plant's ceiling on both outputs with its mass within 10 %. Only that candidate (a shorter
    test; the full vocabulary names the same)."""
    _named_at_the_ceiling(2017)


def test_a_heavy_mass_far_from_the_ranked_frequency_is_found_from_a_grid():
    """Seen held-out two-mass/extra_mode/2497 (judged in session 41: ``unexplained``): 1.7 kg at
    9 Hz on the head, a chirp at 50 Hz; the nominal's contact-force fit 52 %, the plant's 97.9 %.
    The ranked start (the additive mode's 20 Hz, 2 % of the head) led the refit to ``m_e = 0``,
    where ``f_e`` has no gradient; the grid of masses and frequencies
    (:func:`~panto.identification.diagnosis.refit.located_mode`) starts it in the right basin:
    the plant's ceiling on every output, the mass within 10 %."""
    _named_at_the_ceiling(2497)


def test_friction_and_springs_are_ranked_through_the_extra_mass():
    """Once a mass on the head is accepted, the next round ranks friction on each mass and each
    spring's stiffening through the model's own dynamics, its extra states included (the force
    vectors were sized for the bare oscillator: seen on the tuning split, three-mass/
    hysteresis/56, a crash); a force on the head reaches the contact force through the mode."""
    from panto.identification.diagnosis.augmentations import AugmentedStructure
    from panto.identification.diagnosis.effects import SignalRoles
    from panto.identification.diagnosis.ranking import mass_friction, spring_stiffening
    from panto.identification.diagnosis.refit import Model

    roles = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position="y_cb",
                        head_position=None)
    n = 400
    t = np.arange(n) * 0.01
    eta = 2.05 + 0.002 * np.sin(2 * np.pi * 1.3 * t)
    data = IdentificationData(t, np.column_stack([eta, np.full(n, 4.0)]), np.zeros((n, 2)),
                              ("eta", "p"), ("F_c", "y_cb"))
    structure = AugmentedStructure(OscillatorStructure(3, outputs=("F_c", "y_cb")), "extra_mode",
                                   roles, {"output": "F_c", "attached": 3, "frequency_hz": 7.0})
    model = Model(structure, {**structure.nominal(), **MODE}, ())
    for regressors, paths in (mass_friction(model, data), spring_stiffening(model, data)):
        assert regressors and len(paths) == len(regressors)
        assert all(p.shape == (n, 2) and np.all(np.isfinite(p)) for p in paths.values())
        assert any(np.max(np.abs(p[:, 0])) > 0 for p in paths.values())


def test_the_mode_grid_leaves_other_effects_and_the_additive_mode_alone():
    """refit.py ``located_mode`` changes only an extra mass inside an oscillator: an additive
    mode's or a lag's start comes back as it went in, and a mass inside starts at a grid point
    no costlier than its start."""
    from panto.identification.diagnosis.augmentations import AugmentedStructure
    from panto.identification.diagnosis.effects import SignalRoles
    from panto.identification.diagnosis.refit import located_mode

    roles = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position=None,
                        head_position=None)
    n = 400
    t = np.arange(n) * 0.02
    eta = 2.05 + 0.002 * np.sin(2 * np.pi * 1.3 * t) + 0.001 * np.sin(2 * np.pi * 6.1 * t)
    inputs = np.column_stack([eta, np.full(n, 4.0)])
    truth = OscillatorWithMode(2, outputs=("F_c",))
    data = IdentificationData(t, inputs, np.zeros((n, 1)), ("eta", "p"), ("F_c",))
    measured = truth.simulate({**truth.nominal(), "m_e": 1.5, "f_e": 5.0, "zeta_e": 0.05}, data)
    data = IdentificationData(t, inputs, measured, ("eta", "p"), ("F_c",))
    plain = OscillatorStructure(2, outputs=("F_c",))
    for effect, setting in (("extra_mode", {"output": "F_c", "frequency_hz": 20.0}),
                            ("actuator_lag", {"input": "eta"})):
        other = AugmentedStructure(plain, effect, roles, setting)
        start = other.nominal()
        assert located_mode(other, start, data) == start
    inside = AugmentedStructure(plain, "extra_mode", roles,
                                {"output": "F_c", "attached": 2, "frequency_hz": 20.0})
    start = inside.nominal()
    located = located_mode(inside, start, data)
    assert located != start and abs(located["f_e"] - 5.0) < 1.5, located
