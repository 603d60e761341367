"""The thesis' rig story on the virtual test bed (issue 8, last proof item), short runs of
docs/diagnosis/rig_story.py: the force sensor's aluminium bar (1.5 kg, ``F_sensor = F_c - m_bar
eta''``) and the lower-arm hinge friction (20 N m) are hidden in the rig; the nominal is the
linearised physical model fitted on an APRBS run; a second APRBS run is withheld for judging;
a slow ramp run and clean-rig twins (same inputs and noise, no effect) locate the friction.

The story, as physics says it must read:

- *where*: the gap is in the force channel, most of its energy above 2 Hz; the bar's force
  ``m_bar eta''`` lives where the motor accelerates (the part of the gap the bar closes is much
  larger during the motor's strongest accelerations than elsewhere); the hinge friction shows on
  the ramps' slow motion, where a clean rig's nominal leaves only the noise;
- *which*: the diagnosis accepts both ``coulomb_friction`` and ``sensor_inertia``;
- *how far*: each of the two raises the withheld run's force fit when it is added, and the
  final model shrinks the ramps' slow-motion residual (the friction's part).
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "diagnosis" / "rig_story.py"


def _load_script():
    spec = importlib.util.spec_from_file_location("rig_story", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def story():
    """25 s APRBS runs and a 30 s ramp run at the script's 50 Hz; two effects at most."""
    return _load_script().tell_story(25.0, 30.0, max_effects=2)


def _step(story, effect):
    steps = [s for s in story["steps"] if s["effect"] == effect]
    assert steps, f"{effect} not accepted: {story['effects']}"
    return steps[0]


def test_the_force_gap_lies_at_the_higher_frequencies_during_motor_acceleration(story):
    """The nominal's force residual has most of its energy above 2 Hz; the part the bar
    explains (the final model with the bar's mass set to 0, everything else kept) lies where the
    motor accelerates most (top 10 % of ``|eta''|``): twice the RMS there than elsewhere."""
    assert story["validation_fit_before"]["F_c"] < story["validation_fit_before"]["y_cb"]
    assert story["where_validation_before"]["share_above_2_hz"] > 0.5
    bar = story["where_validation_final_without"]["sensor_inertia"]
    assert bar["share_above_2_hz"] > 0.5, bar
    assert bar["high_band_rms_strong_acceleration_N"] > 2.0 * bar["high_band_rms_other_N"], bar


def test_the_friction_shows_on_the_slow_ramps(story):
    """Against the clean rig's nominal on the clean ramp run (the noise floor, about the force
    sensor's 1 N noise filtered to 50 Hz), the slow-motion residual is several times larger."""
    ramps, clean = story["where_ramps_nominal"], story["where_clean_ramps_clean_nominal"]
    assert ramps["rms_slow_motion_N"] > 3.0 * clean["rms_slow_motion_N"], (ramps, clean)


def test_the_diagnosis_names_friction_and_the_bar(story):
    assert story["verdict"] == "effect"
    assert {"coulomb_friction", "sensor_inertia"} <= set(story["effects"]), story["effects"]


def test_each_effect_closes_its_part_of_the_gap_on_the_withheld_run(story):
    for effect in ("coulomb_friction", "sensor_inertia"):
        step = _step(story, effect)
        assert step["fit_after"]["F_c"] > step["fit_before"]["F_c"] + 0.3, step
        assert step["energy_removed"]["F_c"] > 0.1, step
    # the friction's part: the ramps' slow-motion residual shrinks with the final model
    nominal, final = story["where_ramps_nominal"], story["where_ramps_final"]
    assert final["rms_slow_motion_N"] < 0.7 * nominal["rms_slow_motion_N"], (nominal, final)


def test_the_fitted_effects_have_the_hidden_magnitudes(story):
    """The bar's mass and the friction's equivalent bellow pressure (``T_f / k_p``, 20 N m over
    260 N m/bar) come out near the hidden values: within four standard deviations or 25 % (the
    linearised model's remaining error biases them slightly)."""
    truth = story["truth"]
    for effect, key, value in (("sensor_inertia", "sensor_inertia:F_c", truth["bar_mass_kg"]),
                               ("coulomb_friction", "coulomb_friction:p",
                                truth["equivalent_pressure_bar"])):
        step = _step(story, effect)
        estimate, std = abs(step["parameters"][key]), step["std"][key]
        assert abs(estimate - abs(value)) < max(4 * std, 0.25 * abs(value)), (effect, step)
