"""An offset that changes between the runs (a force sensor re-zeroed between them): the training
run cannot show it (the nominal's static force absorbs the training zero), so the ``offset``
candidate's between-runs variant measures the shift on the withheld run's first fold and is judged
on the others (identification/diagnosis/run_offset.py)."""
from __future__ import annotations

import numpy as np

from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.diagnosis.run_offset import judge_shift, shifts
from panto.identification.estimation.base import IdentificationData

from test_diagnosis_effects import _data


def _run(y: np.ndarray) -> IdentificationData:
    t = np.arange(len(y)) * 0.02
    return IdentificationData(t, np.zeros((len(y), 1)), y[:, None], ("u",), ("F",))


def _judged(residual_mean: np.ndarray, seed: int = 0) -> tuple[dict, dict]:
    """A withheld run whose model error is `residual_mean` plus white noise of 1 N around a
    20 N rms signal the model reproduces exactly."""
    rng = np.random.default_rng(seed)
    n = len(residual_mean)
    model = 20.0 * np.sin(np.arange(n) * 0.05)
    data = _run(model + residual_mean + rng.normal(size=n))
    shift = shifts(data, model[:, None], 4)[0]
    return shift, judge_shift(shift, data, model[:, None], 4)


def test_a_constant_shift_is_measured_on_the_first_fold_and_accepted():
    shift, trial = _judged(np.full(2000, 3.0))
    assert abs(shift["shift"] - 3.0) < 4 * shift["std"], shift["shift"]
    assert 0.0 < shift["std"] < 0.2  # 1 N white noise over 500 samples: 0.045 N
    assert trial["accepted"], trial["failed"]
    # the first fold is the tare: its free run is left as it was, so it gains nothing
    assert trial["fold_improvements"][0] == 0.0
    assert all(v > 0 for v in trial["fold_improvements"][1:])


def test_no_shift_is_not_accepted():
    for seed in range(5):
        _, trial = _judged(np.zeros(2000), seed)
        assert not trial["accepted"], (seed, trial)


def test_a_residual_mean_that_is_no_constant_of_the_run_is_rejected():
    """A start transient (3 N decaying in 5 s) sets the first fold's mean; applied to the rest of
    the run it makes the fit worse."""
    t = np.arange(2000) * 0.02
    _, trial = _judged(3.0 * np.exp(-t / 5.0))
    assert not trial["accepted"]
    assert any("worse" in f or "not above" in f for f in trial["failed"]), trial["failed"]


def test_a_force_sensor_rezeroed_between_the_runs_is_named_offset_with_its_shift():
    """Training and withheld runs of the linearised physical model; the withheld run's force
    reads 4 N high (a 1 N noise sensor): no library effect changes between runs, the
    between-runs offset names it and recovers the 4 N (that it names nothing on a clean withheld
    run: test_no_shift_is_not_accepted here, and the clean cases of the independent families,
    benchmarks/diagnosis_families_*.md)."""
    train = _data(None, {}, {}, 1)
    clean = _data(None, {}, {}, 2)
    shifted = IdentificationData(clean.time, clean.inputs, clean.outputs + np.array([4.0, 0.0]),
                                 clean.input_names, clean.output_names)
    result = diagnose(train, shifted, structure="physical-linear",
                      options=DiagnosisOptions(max_effects=1, workers=1, adequacy=False))
    assert result.effects == ("offset",), result.summary
    step = result.steps[0]
    (key, value), = step.parameters.items()
    assert key.startswith("offset:F_c"), key
    assert abs(value - 4.0) < max(4 * step.std[key], 0.4), (value, step.std)
    assert result.fit_after["F_c"] > result.fit_before["F_c"] + 2.0
