"""An actuator lag's frequency response and its global refit (identification/diagnosis/
augmentations.py ``AugmentedStructure._lagged_system``, refit.py ``_second_start``,
``GLOBAL_AFTER_DEFAULTS``). A nominal fitted without a slow bellow lag bends into the shape of an
extra mode; a lag refitted from there, or from the defaults, stopped short of the plant and the
mode was named (seen held-out three-mass/actuator_lag/2120, 0.096 s on the pressure). A lag
that after the defaults' start still leaves the model more than 2 points below the adequacy's
linear black box, though they lower its training cost by more than their BIC penalty (dBIC <
0), now gets the nominal's global method, whose data-driven starts match the lagged structure's
own frequency response to the adequacy's black box (the data's H1 estimate before session 44,
with the pressure's columns masked in session 43)."""
from __future__ import annotations

import numpy as np
from scipy import signal as sps

from fixtures.excitations import load_benchmark, wire_and_pressure

from panto.identification.diagnosis.augmentations import AugmentedStructure
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

ROLES = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position="y_cb",
                    head_position=None)
OUTPUTS = ("F_c", "y_cb")


def _worst_error(rate: float, lag: float, name: str = "p") -> tuple[float, float]:
    """The largest difference, as a share of the output's spread, between ``lsim`` of the lagged
    structure's ``linear_system`` and its own free run (deviations from the first sample's
    equilibrium), and between the free runs with and without the lag (what the lag does)."""
    n = int(20 * rate)
    t, eta, p = wire_and_pressure(np.random.default_rng(4), n, rate, amplitude=0.003,
                                  frequencies=(0.4, 1.1, 2.3, 3.7), hold=(0.5, 2.0),
                                  levels=(3.6, 4.4))
    data = IdentificationData(t, np.column_stack([eta, p]), np.zeros((n, 2)), ("eta", "p"),
                              OUTPUTS)
    structure = AugmentedStructure(OscillatorStructure(3, outputs=OUTPUTS), "actuator_lag", ROLES,
                                   {"input": name, "time_constant_s": lag})
    values = {**structure.nominal(), f"actuator_lag:{name}": lag}
    a, b, c, d = structure.linear_system(values, data)
    simulated = structure.simulate(values, data)
    linear = sps.lsim((a, b, c, d), data.inputs - data.inputs[0], t, interp=True)[1]
    unlagged = structure.simulate({**values, f"actuator_lag:{name}": 0.0}, data)
    scale = np.std(simulated, axis=0)
    error = np.max(np.abs(linear - (simulated - simulated[0])) / scale)
    return float(error), float(np.max(np.abs(unlagged - simulated) / scale))


def test_the_lagged_frequency_response_is_its_free_run_to_second_order():
    """The free run holds the lagged input linear between samples (exact for the lag itself, not
    for what it drives): the two paths agree to O(h^2), four times the rate a sixteenth of the
    error, and far closer than the lag's own effect; on the pressure, and on the wire height,
    which also reaches the contact force directly (its ``D`` column, now the lag state's)."""
    for name, bound in (("p", 1e-3), ("eta", 3e-3)):  # measured 2.1e-4 and 1.5e-3
        coarse, effect = _worst_error(100.0, 0.1, name)
        fine, _ = _worst_error(400.0, 0.1, name)
        assert fine < bound and effect > 0.2, (name, fine, effect)
        assert coarse / fine > 10.0, (name, coarse, fine)


def test_a_slow_bellow_lag_bent_into_a_mode_is_named_with_its_time_constant():
    """The seen held-out case three-mass/actuator_lag/2120 (benchmarks/effect_plants.py, a
    plant written apart from the diagnosis: 0.096 s on the pressure, contact force only, 50 Hz):
    the lag, on ``p``, within 10 % of its time constant, the withheld fit within 0.2 points of
    the plant's own ceiling (without the global refit: ``extra_mode`` then ``sensor_inertia``).
    The lag alone (a shorter test: from the refits without the global one it validated 2.3
    points worse than the nominal and was rejected; the full vocabulary names the lag, with the
    mass on the head at +9.5 points second to its +10.2)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("three-mass", "actuator_lag", 2120, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1),
                      structure="three-mass",
                      options=DiagnosisOptions(candidates=("actuator_lag",),
                                               discovery=False, challenge=False, workers=1))
    assert result.effects[:1] == ("actuator_lag",), result.summary
    truth = case.plant.setting["T"]
    assert "actuator_lag:p" in result.final_parameters, result.summary
    assert abs(result.final_parameters["actuator_lag:p"] - truth) < 0.1 * truth, \
        (result.final_parameters, truth)
    assert result.fit_after["F_c"] > case.ceiling["F_c"] - 0.2, (result.summary, case.ceiling)


def test_a_strong_lag_an_extra_mode_imitates_is_named_once_its_time_constant_is_screened_on_a_log_scale():
    """The seen held-out case two-mass/actuator_lag/4895 (0.026 s on ``eta``, contact force only,
    a 241-point effect): an extra mode imitating the lag's phase won round 1 while every start
    of the lag's global refit ended at 86.8 % training fit; the frequency mapping screened the
    time constant uniformly over [0, 100 T0] (global_fit._screened). Screened log-uniformly the
    lag is named alone, within 3 % of its time constant, at the plant's own validation fit
    (with the uniform screening: ``extra_mode``, F_c 87.0 % against the ceiling's 91.3 %)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "actuator_lag", 4895, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("actuator_lag", "extra_mode"),
                                               discovery=False, challenge=False, workers=1))
    truth = case.plant.setting["T"]
    assert result.effects == ("actuator_lag",), result.summary
    assert abs(result.final_parameters["actuator_lag:eta"] - truth) < 0.03 * truth, \
        (result.final_parameters, truth)
    assert result.fit_after["F_c"] > case.ceiling["F_c"] - 0.2, (result.summary, case.ceiling)
