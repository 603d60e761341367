"""Backward elimination after the search (identification/diagnosis/backward.py): an effect the
withheld run does not need beside the others is dropped, one it needs is kept. Plants written
here: a second-order system behind a first-order actuator lag and, for the second, an input delay
as well (SciPy's first-order-hold discretisation and a whole-sample shift, not the diagnosis' own
filters); nominal ``linear-2``."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis import backward
from panto.identification.diagnosis.nominal import fit_nominal
from panto.identification.diagnosis.pipeline import DiagnosisOptions
from panto.identification.diagnosis.refit import Model, Search, try_candidate
from panto.identification.diagnosis.support import build_structure, default_roles
from panto.identification.estimation.base import IdentificationData

RATE = 50.0
LAG = 0.12  # s
DELAY = 5  # samples (0.1 s)


def _run(seed: int, delay: int = 0, n: int = 1500) -> IdentificationData:
    rng = np.random.default_rng(seed)
    u = 2.0 * signal.lfilter(*signal.butter(2, 0.15), rng.normal(size=n))
    shifted = np.concatenate([np.zeros(delay), u[:n - delay]])
    lagged = signal.dlsim(signal.cont2discrete(([1.0], [LAG, 1.0]), 1.0 / RATE, method="foh"),
                          shifted)[1][:, 0]
    bd, ad = signal.bilinear([36.0], [1.0, 3.0, 36.0], fs=RATE)
    y = signal.lfilter(bd, ad, lagged)
    y = y + 0.01 * np.std(y) * rng.normal(size=n)
    return IdentificationData(np.arange(n) / RATE, u[:, None], y[:, None], ("u",), ("y",))


def _stacked(effects: list[dict], delay: int):
    """The nominal fitted to the training run, then each candidate in `effects` refitted on top
    of the model before it (as the forward search would have accepted them)."""
    train, validation = _run(1, delay), _run(2, delay)
    structure, free = build_structure("linear-2", train, {})
    result = fit_nominal(structure, free, train)
    nominal = Model(structure, dict(result.parameters), tuple(free), dict(result.std),
                    np.asarray(result.covariance, float), dict(result.fit))
    search = Search(train, validation, default_roles(structure, train), DiagnosisOptions(),
                    {"max_evaluations": 400}, lambda line: None)
    model, current = nominal, structure.simulate(nominal.parameters, validation)
    trials = []
    for candidate in effects:
        trial, model, current = try_candidate(model, candidate, current, search)
        assert trial.parameters, trial.message  # refitted
        trials.append(trial)
    return nominal, model, current, search, trials


LAG_CANDIDATE = {"effect": "actuator_lag", "variant": "lag(u, 0.05 s)", "err": 0.5,
                 "setting": {"input": "u", "time_constant_s": 0.05}}
DELAY_CANDIDATE = {"effect": "input_delay", "variant": "delay(u, 0.02 s)", "err": 0.5,
                   "setting": {"input": "u", "delay_s": 0.02}}


def test_an_effect_the_others_make_superfluous_is_dropped_and_the_needed_one_kept():
    # the plant has a lag only: a delay accepted first (it imitates part of the lag's phase) is
    # superfluous once the lag is in the model
    nominal, model, current, search, _ = _stacked([DELAY_CANDIDATE, LAG_CANDIDATE], delay=0)
    eliminated = backward.eliminate(nominal, model, current, ["input_delay", "actuator_lag"],
                                    search)
    assert eliminated is not None
    assert [d["effect"] for d in eliminated["dropped"]] == ["input_delay"]
    assert eliminated["kept"] == [1]
    kept = eliminated["model"]
    assert "input_delay:u" not in kept.parameters
    assert kept.parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)
    # the kept effect's step is judged against the nominal and passes on its own
    before = nominal.structure.simulate(nominal.parameters, search.validation)
    (trial, run_before, after), = backward.rejudged(
        nominal, before, eliminated, [None, _trial_of(LAG_CANDIDATE)], search)
    assert trial.effect == "actuator_lag" and trial.accepted
    assert run_before is before
    assert np.array_equal(after, eliminated["simulated"])


def test_two_effects_the_plant_has_are_both_kept():
    nominal, model, current, search, _ = _stacked([LAG_CANDIDATE, DELAY_CANDIDATE], delay=DELAY)
    # the nominal's two-coefficient numerator can take up to one sample of the delay
    assert model.parameters["input_delay:u"] == pytest.approx(DELAY / RATE, abs=1.2 / RATE)
    assert model.parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)
    assert backward.eliminate(nominal, model, current, ["actuator_lag", "input_delay"],
                              search) is None


def test_the_stack_is_read_through_a_pickled_copy():
    # a round's refits come back from worker processes as copies of the nominal
    nominal, model, _, _, _ = _stacked([LAG_CANDIDATE], delay=0)
    copy = pickle.loads(pickle.dumps(model.structure))
    assert [e for e, _ in backward.layers(copy, nominal.structure)] == ["actuator_lag"]
    other, _ = build_structure("linear-3", _run(1), {})
    assert backward.layers(copy, other) is None


def _trial_of(candidate):
    from types import SimpleNamespace

    return SimpleNamespace(effect=candidate["effect"], variant=candidate["variant"],
                           err=candidate["err"])


def test_the_diagnosis_keeps_the_needed_effect_s_step_judged_against_the_nominal():
    """The pipeline's use of the elimination (pipeline._eliminated): from the search's accepted
    trials (a delay, then the lag the plant has) to the kept model's free run and steps: one step,
    the lag's, from the nominal's validation fit to the kept model's; the dropped delay named
    with its round; nothing done after an offset between the runs."""
    import dataclasses

    from panto.identification.diagnosis import pipeline, run_offset
    from panto.identification.diagnosis.nominal import fit_per_output

    nominal, model, current, search, trials = _stacked([DELAY_CANDIDATE, LAG_CANDIDATE], delay=0)
    before = nominal.structure.simulate(nominal.parameters, search.validation)
    steps = [pipeline._step(trials[0], search.validation, before, before)] * 2  # only read
    # for their alternatives and evidence here
    kept_model, kept_run, kept_steps, dropped = pipeline._eliminated(
        nominal, model, before, current, steps, trials, search)
    assert [s.effect for s in kept_steps] == ["actuator_lag"]
    assert kept_steps[0].fit_before == fit_per_output(search.validation, before)
    assert kept_steps[0].fit_after == fit_per_output(search.validation, kept_run)
    assert kept_steps[0].fit_after["y"] > 98.0
    assert "input_delay:u" not in kept_model.parameters
    assert [(d["index"], d["effect"]) for d in dropped] == [(0, "input_delay")]
    assert "input_delay was accepted in round 1 and dropped" in backward.dropped_text(dropped)
    offset = [dataclasses.replace(trials[0], variant=run_offset.VARIANT), trials[1]]
    assert pipeline._eliminated(nominal, model, before, current, steps, offset, search) is None
