"""A heavy mass between the head and the force sensor (identification/diagnosis/augmentations.py
``sensor_inertia``, refit.py ``global_refit``). The measured force is ``F_c + m_s xi''``; the
nominal fitted without it bends far from its own parameters to absorb it, and a refit from there
(or from the defaults) stopped at 84.7 % where the plant reaches 98.6 % (seen held-out case
two-mass/sensor_inertia/1896, 3.9 kg: an extra mode was named). The head's acceleration is now
the oscillator's own (``A x + B u`` at each sample, not a second difference of its position),
the augmented structure gives its frequency response, and the refit's second start is the
nominal's global method."""
from __future__ import annotations

import numpy as np
from scipy import signal as sps

from fixtures.excitations import load_benchmark, wire_and_pressure

from panto.identification.diagnosis.augmentations import AugmentedStructure, simulating
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

ROLES = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position=None,
                    head_position="xi")


def _inputs(seed: int, n: int, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, a multisine of the wire height up to 12 Hz and pressure steps held 0.5-2 s."""
    return wire_and_pressure(np.random.default_rng(seed), n, rate, amplitude=0.002,
                             frequencies=(0.5, 1.3, 2.9, 4.7, 7.1, 9.7, 12.1), hold=(0.5, 2.0),
                             levels=(3.7, 4.3))


def test_the_head_acceleration_is_the_limit_of_its_second_difference():
    """The exact ``xi''`` of a run at 2 kHz against the second difference of its ``xi``: they
    agree to the difference's O(T^2) error, and the bar's ``y_cb''`` likewise."""
    t, eta, p = _inputs(1, 8000, 2000.0)
    structure = simulating(simulating(OscillatorStructure(3, outputs=("xi", "y_cb")), "xi''"),
                           "y_cb''")
    y = structure.simulate(structure.nominal(), IdentificationData(
        t, np.column_stack([eta, p]), np.zeros((len(t), 4)), ("eta", "p"), structure.output_names))
    for position, exact in ((0, 2), (1, 3)):
        second = (y[2:, position] - 2 * y[1:-1, position] + y[:-2, position]) * 2000.0 ** 2
        error = np.max(np.abs(second[10:] - y[11:-1, exact]))
        assert error < 0.02 * np.max(np.abs(y[:, exact])), (position, error)


def test_the_augmented_frequency_response_is_its_free_run():
    """Two paths: ``lsim`` of the augmented structure's ``linear_system`` against its own
    simulation, as deviations from the first sample's equilibrium."""
    t, eta, p = _inputs(2, 1500, 100.0)
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((len(t), 2)), ("eta", "p"),
                              ("F_c", "y_cb"))
    structure = AugmentedStructure(OscillatorStructure(2, outputs=("F_c", "y_cb")),
                                   "sensor_inertia", ROLES, {"signal": "xi", "scale": 1.0})
    values = {**structure.nominal(), "sensor_inertia:F_c": -2.0}
    a, b, c, d = structure.linear_system(values, data)
    simulated = structure.simulate(values, data)
    linear = sps.lsim((a, b, c, d), data.inputs - data.inputs[0], t, interp=True)[1]
    scale = np.std(simulated, axis=0)
    assert np.all(np.max(np.abs(linear - (simulated - simulated[0])), axis=0) < 1e-8 * scale)


def test_a_twin_keeps_its_own_acceleration_and_a_cubic_oscillator_offers_none():
    """The copy :func:`simulating` makes (one output more) simulates its own columns whichever
    of it and its original ran first (they shared the exact-acceleration cache); a nonlinear
    oscillator offers no exact acceleration (``A x + B u`` leaves out its nonlinear forces), so
    a sensor mass on it takes the second difference of the head it simulates."""
    from panto.identification.structures.oscillator_effects import NonlinearOscillator

    t, eta, p = _inputs(5, 300, 100.0)
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((len(t), 2)), ("eta", "p"),
                              ("F_c", "y_cb"))
    for order in (0, 1):
        original = AugmentedStructure(OscillatorStructure(2, outputs=("F_c", "y_cb")),
                                      "sensor_inertia", ROLES, {"signal": "xi", "scale": 1.0})
        twin = simulating(original, "xi")
        values = {**original.nominal(), "sensor_inertia:F_c": -2.0}
        for structure in ((original, twin) if order == 0 else (twin, original)):
            assert structure.simulate(values, data).shape == (len(t), len(structure.output_names))
    cubic = NonlinearOscillator(2, cubic=True, outputs=("F_c",))
    assert simulating(cubic, "xi''") is None
    augmented = AugmentedStructure(cubic, "sensor_inertia", ROLES, {"signal": "xi", "scale": 1.0})
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((len(t), 1)), ("eta", "p"),
                              ("F_c",))
    y = augmented.simulate({**augmented.nominal(), "sensor_inertia:F_c": -2.0}, data)
    assert y.shape == (len(t), 1) and np.all(np.isfinite(y))


def test_a_heavy_sensor_mass_is_named_with_its_mass():
    """The seen held-out case two-mass/sensor_inertia/1896 (benchmarks/effect_plants.py, a plant
    written apart from the diagnosis: 3.9 kg above the head, contact force only, multisine at
    100 Hz): named first with its mass within 1 % and the withheld fit at the plant's own
    ceiling (without the global refit: ``extra_mode``, 70.1 -> 93.9 %). The two candidates that
    competed there only (the full vocabulary names the same; a shorter test)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "sensor_inertia", 1896, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("sensor_inertia", "extra_mode"),
                                               discovery=False, challenge=False, workers=1))
    assert result.effects[:1] == ("sensor_inertia",), result.summary
    truth = case.plant.setting["m_s"]  # measured F_c + m_s xi'': the augmentation's F - m a
    assert abs(-result.final_parameters["sensor_inertia:F_c"] - truth) < 0.01 * truth, \
        (result.final_parameters["sensor_inertia:F_c"], truth)
    assert result.fit_after["F_c"] > case.ceiling["F_c"] - 0.1, (result.summary, case.ceiling)


def test_a_sensor_mass_gets_its_global_refit_where_the_black_box_does_not_validate():
    """The seen held-out case three-mass/sensor_inertia/411 (3.3 kg above the head, contact force
    only, a multisine at 50 Hz whose validation run sits elsewhere): the adequacy's black box
    fits the training run 2.9 points above the nominal (F test p ~ 1e-253: the structure cannot
    express it) but validates at 60.6 % against the nominal's 72.6 %, so the validation-side
    test of missing linear dynamics gave the sensor mass no global refit and its local refits
    found nothing (``unexplained``; with the full vocabulary an extra mode at 20 Hz was named).
    The training-side test gave it (refit.py ``lacks_linear_dynamics``). Since the nominal's
    global fit matches the black box's response (global_fit.py ``reference_response``) the
    nominal absorbs the mass to 0.7 training points of the black box (validation 94.6 %), no
    shortfall calls for a second start, and the refit from the nominal gains dBIC -53 on
    training while losing 0.74 points on the validation run: ``refit.trapped`` gives it its
    global refit, whose mapping also polishes the nominal's candidates (``seeds``). Named, its
    mass within 5 %, the withheld fit within 0.2 points of the plant's own. The sensor mass
    alone (a shorter test)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("three-mass", "sensor_inertia", 411, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="three-mass",
                      options=DiagnosisOptions(candidates=("sensor_inertia",),
                                               discovery=False, challenge=False, workers=1))
    assert result.effects[:1] == ("sensor_inertia",), result.summary
    truth = case.plant.setting["m_s"]
    assert abs(-result.final_parameters["sensor_inertia:F_c"] - truth) < 0.05 * truth, \
        (result.final_parameters["sensor_inertia:F_c"], truth)
    assert result.fit_after["F_c"] > case.ceiling["F_c"] - 0.2, (result.summary, case.ceiling)


def test_a_sensor_mass_refit_matched_to_the_black_box_reaches_the_plant():
    """The seen held-out case two-mass/sensor_inertia/1386 (0.96 kg above the head, contact force
    only, a chirp at 100 Hz, 20 s): the H1 estimate of so short a record leaks (the plant's own
    parameters have weighted error rms 29 against it), the global refit's data-driven starts
    matched it in another basin and the sensor mass validated at 97.0 % (0.86 kg) against the
    plant's 97.9 % (with the full vocabulary an extra mode at 0.11 Hz won). Matched to the
    adequacy's black box instead (rms 1.0 at the plant's parameters; global_fit.py
    ``reference_response``): the mass within 2 %, the withheld fit within 0.1 points of the
    plant's own. The sensor mass alone (a shorter test)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "sensor_inertia", 1386, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("sensor_inertia",),
                                               discovery=False, challenge=False, workers=1))
    assert result.effects[:1] == ("sensor_inertia",), result.summary
    truth = case.plant.setting["m_s"]
    assert abs(-result.final_parameters["sensor_inertia:F_c"] - truth) < 0.02 * truth, \
        (result.final_parameters["sensor_inertia:F_c"], truth)
    assert result.fit_after["F_c"] > case.ceiling["F_c"] - 0.1, (result.summary, case.ceiling)


def test_a_sensor_mass_is_refitted_in_the_head_as_well_as_on_the_wire():
    """The seen held-out case two-mass/sensor_inertia/2106 (1.04 kg above the head, contact
    force and cross-bar height measured, the head not; a chirp at 50 Hz): the ranking's best
    placement of the mass is on the wire (``eta''``, a second difference of the input), whose
    refit gained +0.35 points and lost to an extra mode's +0.71. Both placements are refitted
    (refit.py ``try_candidate``): the head's, with its exact acceleration, reaches the lower
    training cost and is kept, named first with its mass within 2 %."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "sensor_inertia", 2106, quick=True),
                              scored=False)
    lines: list[str] = []
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("sensor_inertia", "extra_mode"),
                                               discovery=False, challenge=False, workers=1),
                      progress=lines.append)
    tried = {line.split(":")[0].strip() for line in lines if "dBIC" in line}
    assert {"sensor_inertia@eta", "sensor_inertia@xi"} <= tried, tried
    assert any(line.strip().startswith("sensor_inertia: kept on xi''") for line in lines), lines
    assert result.effects[:1] == ("sensor_inertia",), result.summary
    assert "the mass moves with xi" in result.steps[0].description, result.steps[0].description
    truth = case.plant.setting["m_s"]
    assert abs(-result.final_parameters["sensor_inertia:F_c"] - truth) < 0.02 * truth, \
        (result.final_parameters["sensor_inertia:F_c"], truth)


def test_a_sensor_mass_on_a_contact_loss_model_follows_the_second_difference_of_its_head():
    """A model with a unilateral contact (an accepted ``contact_loss``) simulates the head but
    not its exact acceleration (the contact switches the dynamics): a sensor mass on the head
    takes the head's second difference there instead of failing (seen held-out
    two-mass/contact_loss/2138: the head placement's refit failed on an unknown output
    ``xi''``). Its force column is the contact model's less the mass times that difference."""
    t, eta, p = _inputs(4, 600, 100.0)
    names = ("F_c", "y_cb", "xi")
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((len(t), 3)), ("eta", "p"),
                              names)
    contact = AugmentedStructure(OscillatorStructure(2, outputs=names), "contact_loss", ROLES,
                                 {"output": "F_c"})
    assert simulating(contact, "xi''") is None and simulating(contact, "xi") is None
    mass = AugmentedStructure(contact, "sensor_inertia", ROLES,
                              {"signal": "xi", "output": "F_c", "scale": 1.0})
    values = {**mass.nominal(), "sensor_inertia:F_c": -2.0}
    with_mass, without = mass.simulate(values, data), contact.simulate(contact.nominal(), data)
    xi = without[:, 2]
    second = (xi[2:] - 2 * xi[1:-1] + xi[:-2]) / (t[1] - t[0]) ** 2
    assert np.allclose(with_mass[:, 1:], without[:, 1:])
    assert np.allclose(with_mass[1:-1, 0], without[1:-1, 0] + 2.0 * second,
                       atol=1e-9 * np.max(np.abs(without[:, 0])))
