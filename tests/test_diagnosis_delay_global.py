"""An input delay's frequency response and its global refit (identification/estimation/
global_fit.py ``_FrequencyProblem.delays``/``delayed``, identification/diagnosis/augmentations.py
``AugmentedStructure.input_delays``). A delay has no rational ``(A, B, C, D)``; before session 53
its global refit could not map the frequency response, so a nominal bent by a strong delay was
refitted with the delay from the bent parameters and from the defaults only, and an extra mode,
which the global method does map, imitated the delay better (seen held-out two-mass/
input_delay/5554, 11.9 ms at 100 Hz: the delay's refit stopped 0.27 points below the plant's
ceiling and the mode was named). The mapping now multiplies the delayed input's column by
``exp(-j w d)``."""
from __future__ import annotations

import numpy as np
import pytest

from fixtures.excitations import load_benchmark, wire_and_pressure

from panto.identification.diagnosis.augmentations import AugmentedStructure
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.estimation.base import IdentificationData
from panto.identification.estimation.global_fit import initial_from_data
from panto.identification.structures.oscillators import OscillatorStructure

ROLES = SignalRoles(position="eta", force="F_c", actuators=("eta", "p"), sensor_position="y_cb",
                    head_position=None)
RATE, SAMPLES = 100.0, 2000


@pytest.mark.parametrize("truth", [0.004, 0.023])
def test_the_frequency_mapping_recovers_a_known_delay(truth):
    """A two-mass oscillator behind a delay of 0.4 or 2.3 samples on the wire height, its
    contact force recorded with 0.1 % noise; everything but the delay at the plant's values and
    the delay started at one sample (0.01 s): the mapping's best candidate within 5 % of the
    delay (it matches the continuous ``exp(-j w d)`` to the H1 estimate of a response the free
    run delays by interpolation; measured 3.7 % and 2.6 % short). Without the delay's factor the
    response does not depend on the delay and the mapping keeps the start."""
    t, eta, p = wire_and_pressure(np.random.default_rng(4), SAMPLES, RATE, amplitude=0.003,
                                  frequencies=(0.4, 1.1, 2.3, 3.7, 5.3, 7.9, 11.3, 16.1),
                                  hold=(0.5, 2.0), levels=(3.6, 4.4))
    inputs = np.column_stack([eta, p])
    structure = AugmentedStructure(OscillatorStructure(2, outputs=("F_c",)), "input_delay",
                                   ROLES, {"input": "eta", "delay_s": 0.01})
    values = {**structure.nominal(), "input_delay:eta": truth}
    clean = structure.simulate(values, IdentificationData(t, inputs, np.zeros((SAMPLES, 1)),
                                                          ("eta", "p"), ("F_c",)))
    noise = 1e-3 * np.std(clean) * np.random.default_rng(1).normal(size=clean.shape)
    data = IdentificationData(t, inputs, clean + noise, ("eta", "p"), ("F_c",))
    candidates = initial_from_data(structure, data, ("input_delay:eta",),
                                   initial={**values, "input_delay:eta": 0.01})
    found = candidates[0].parameters["input_delay:eta"]
    assert found == pytest.approx(truth, rel=0.05), [c.parameters for c in candidates]


def test_a_strong_delay_imitated_by_a_mode_is_named_as_the_delay():
    """The seen held-out case two-mass/input_delay/5554 (benchmarks/effect_plants.py, a plant
    written apart from the diagnosis: 11.9 ms on the wire height, contact force only, 100 Hz,
    the nominal at 53 % against the plant's 92 %), with the delay and the extra mode named in
    its place before (the whole vocabulary names the delay too: benchmarks/results.md, session
    53): the delay named, within 10 % of the
    plant's, and the withheld fit within 0.2 points of the plant's own ceiling (before: the mode
    named at 91.81 %, the delay's refit at 91.78 %, the ceiling 92.05 %)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "input_delay", 5554, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1),
                      structure="two-mass",
                      options=DiagnosisOptions(candidates=("input_delay", "extra_mode"),
                                               discovery=False, challenge=False, workers=1))
    assert result.effects[:1] == ("input_delay",), result.summary
    truth = case.plant.setting["tau"]
    assert result.final_parameters["input_delay:eta"] == pytest.approx(truth, rel=0.1)
    ceiling = case.ceiling["F_c"]
    assert result.fit_after["F_c"] > ceiling - 0.2, (result.fit_after, ceiling)
