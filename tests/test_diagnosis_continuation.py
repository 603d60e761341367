"""A refit that stopped on its budget is continued before two candidates the withheld run cannot
tell apart are ranked by their training dBIC (identification/diagnosis/refit.py continue_refit,
choice.choose_converged). Plant written here: a second-order system behind a first-order actuator
lag (discretised by SciPy with a first-order hold, not by the diagnosis' own filter), nominal
``linear-2``."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis.nominal import fit_nominal
from panto.identification.diagnosis.pipeline import DiagnosisOptions
from panto.identification.diagnosis.choice import choose_converged
from panto.identification.diagnosis.refit import Model, Search, continue_refit, try_candidate
from panto.identification.diagnosis.support import build_structure, default_roles, residuals
from panto.identification.estimation.base import IdentificationData

RATE = 50.0
LAG = 0.12  # s


def _run(seed: int, n: int = 1500, lag: float = LAG) -> IdentificationData:
    rng = np.random.default_rng(seed)
    u = 2.0 * signal.lfilter(*signal.butter(2, 0.15), rng.normal(size=n))
    lagged = signal.dlsim(signal.cont2discrete(([1.0], [lag, 1.0]), 1.0 / RATE, method="foh"),
                          u)[1][:, 0] if lag > 0 else u
    bd, ad = signal.bilinear([36.0], [1.0, 3.0, 36.0], fs=RATE)
    y = signal.lfilter(bd, ad, lagged)
    y = y + 0.01 * np.std(y) * rng.normal(size=n)
    return IdentificationData(np.arange(n) / RATE, u[:, None], y[:, None], ("u",), ("y",))


@pytest.fixture(scope="module")
def stopped():
    train, validation = _run(1), _run(2)
    structure, free = build_structure("linear-2", train, {})
    result = fit_nominal(structure, free, train)
    model = Model(structure, dict(result.parameters), tuple(free), dict(result.std),
                  np.asarray(result.covariance, float), dict(result.fit))
    search = Search(train, validation, default_roles(structure, train), DiagnosisOptions(),
                    {"max_evaluations": 30}, lambda line: None)
    current = structure.simulate(model.parameters, validation)
    candidate = {"effect": "actuator_lag", "variant": "lag(u, 0.02 s)", "err": 0.5,
                 "setting": {"input": "u", "time_constant_s": 0.02}}
    return candidate, try_candidate(model, candidate, current, search), model, current, search


def _as(entry, **changes):
    return (dataclasses.replace(entry[0], **changes),) + tuple(entry[1:])


def _cost(entry, search) -> float:
    _, eps = residuals(entry[1].structure, entry[1].parameters, search.train)
    return float(np.nansum(eps ** 2))


def test_a_refit_stopped_on_its_budget_is_continued_to_a_lower_cost(stopped):
    candidate, entry, model, current, search = stopped
    assert "maximum" in entry[0].message  # 30 simulations do not reach the optimum
    continued = continue_refit(candidate, entry, model, current, search)
    assert "maximum" not in continued[0].message
    assert _cost(continued, search) < _cost(entry, search)
    assert continued[0].delta_bic < entry[0].delta_bic
    assert continued[1].parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)


def test_a_converged_refit_is_left_as_it_is(stopped):
    candidate, entry, model, current, search = stopped
    continued = continue_refit(candidate, entry, model, current, search)
    assert continue_refit(candidate, continued, model, current, search) is continued


def test_the_chosen_refit_is_continued_to_its_optimum_before_it_is_accepted(stopped):
    candidate, entry, model, current, search = stopped
    assert entry[0].accepted and "maximum" in entry[0].message
    trials, chosen = choose_converged([entry], [candidate], model, current, search)
    assert chosen is trials[0] and chosen is not entry
    assert chosen[0].continuation and chosen[0].message.startswith("converged")
    assert _cost(chosen, search) < _cost(entry, search)
    assert chosen[1].parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)


def test_a_rejected_refit_stopped_short_on_the_training_side_is_continued_and_judged(stopped):
    """Its significance was taken where the budget ran out: continued, it is judged at its
    optimum (here the lag the plant has, accepted and chosen)."""
    candidate, entry, model, current, search = stopped
    assert entry[0].improvement > 0.0
    rejected = _as(entry, accepted=False, failed=("|theta|/sigma 2.50 <= 3",))
    trials, chosen = choose_converged([rejected], [candidate], model, current, search)
    assert chosen is trials[0] and chosen[0].continuation and chosen[0].accepted
    assert _cost(chosen, search) < _cost(rejected, search)
    assert chosen[1].parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)


def test_rejected_refits_a_continuation_cannot_help_are_left_alone(stopped):
    candidate, entry, model, current, search = stopped
    for rejected in (
            _as(entry, accepted=False, improvement=-0.5, failed=("dBIC 3.0 >= -10",)),
            _as(entry, accepted=False, message="converged: the gradient vanishes",
                failed=("dBIC 3.0 >= -10",)),
            _as(entry, accepted=False, failed=("y worse on validation by 0.9 points",))):
        trials, chosen = choose_converged([rejected], [candidate], model, current, search)
        assert chosen is None and trials[0] is rejected


def test_the_report_says_when_an_accepted_refit_did_not_converge():
    from panto.identification.diagnosis.pipeline import Step
    from panto.identification.diagnosis.report import _not_converged

    def step(refit):
        return Step("actuator_lag", "lag", {}, {}, {}, {}, {}, {}, {}, refit=refit)

    text = _not_converged(step("not converged: maximum of 1200 model evaluations reached"))
    assert "maximum of 1200 model evaluations" in text and "not shown" in text
    assert _not_converged(step("converged: the gradient vanishes")) == ""


# The selection logic with a stand-in continuation (what continue_refit returns is tested above):
# every trial that could be chosen at its optimum is continued once before the choice.

def _trial(effect, improvement, delta_bic, accepted=True, stopped=True, failed=()):
    from panto.identification.diagnosis.refit import Trial

    message = "not converged: maximum of 400 model evaluations reached" if stopped else \
        "converged: the cost no longer decreases"
    return (Trial(effect, "", 0.0, effect, {}, {}, 5.0, delta_bic, improvement, (), 0.4, {}, {},
                  accepted, tuple(failed), message), None, None)


def _continuing(outcomes, calls):
    """A stand-in for continue_refit: the trial of `outcomes[effect]` (improvement, dBIC,
    accepted) after its continuation."""
    def fake(candidate, entry, model, current, search):
        calls.append(candidate["effect"])
        improvement, delta_bic, accepted = outcomes[candidate["effect"]]
        trial = dataclasses.replace(entry[0], improvement=improvement, delta_bic=delta_bic,
                                    accepted=accepted, failed=() if accepted else ("x",),
                                    continuation="up to 1200 more simulations",
                                    message="converged: the cost no longer decreases")
        return trial, None, None
    return fake


def _choose_with(monkeypatch, trials, outcomes, folds=4):
    from panto.identification.diagnosis import choice

    calls = []
    monkeypatch.setattr(choice, "continue_refit", _continuing(outcomes, calls))
    search = SimpleNamespace(options=SimpleNamespace(folds=folds))
    candidates = [{"effect": t[0].effect} for t in trials]
    trials, chosen = choice.choose_converged(trials, candidates, None, None, search)
    return trials, chosen, calls


def test_a_tie_is_decided_between_optima_after_the_chosen_one_loses_gain(monkeypatch):
    """A (5.0 points) is continued and falls to 3.9; B (4.0, stopped on its budget) is then
    within the tolerance (0.2): it is continued too before dBIC decides, and wins."""
    trials, chosen, calls = _choose_with(
        monkeypatch, [_trial("a", 5.0, -60.0), _trial("b", 4.0, -40.0)],
        {"a": (3.9, -60.0, True), "b": (4.0, -80.0, True)})
    assert calls == ["a", "b"] and chosen[0].effect == "b"


def test_each_contender_is_continued_once_and_a_refit_rejected_at_its_optimum_is_not_chosen(
        monkeypatch):
    trials, chosen, calls = _choose_with(
        monkeypatch, [_trial("a", 5.0, -60.0), _trial("b", 1.0, -40.0)],
        {"a": (5.0, -60.0, False), "b": (1.0, -40.0, True)})
    assert calls == ["a", "b"] and chosen[0].effect == "b" and not trials[0][0].accepted
    trials, chosen, calls = _choose_with(
        monkeypatch, [_trial("a", 5.0, -60.0), _trial("b", 1.0, -40.0, stopped=False)],
        {"a": (5.0, -60.0, False)})
    assert calls == ["a"] and chosen[0].effect == "b"


def test_a_trial_after_the_candidates_is_never_continued_but_sets_the_bar(monkeypatch):
    """The offset between the runs (appended after the refits, no candidate) is chosen as it is;
    a rejected refit far below its gain is not continued."""
    offset = _trial("offset", 6.0, -50.0, stopped=False)
    far = _trial("a", 2.0, -60.0, accepted=False, failed=("|theta|/sigma 2.00 <= 3",))
    from panto.identification.diagnosis import choice

    calls = []
    monkeypatch.setattr(choice, "continue_refit", _continuing({}, calls))
    search = SimpleNamespace(options=SimpleNamespace(folds=4))
    trials, chosen = choice.choose_converged([far, offset], [{"effect": "a"}], None, None, search)
    assert calls == [] and chosen is offset


def test_a_lag_ranked_far_from_the_plant_is_located_on_the_grid_before_the_refit(stopped):
    """With a nominal that has not absorbed the lag (fitted on the same plant without it), the
    grid of sample periods finds the plant's 0.12 s lag (6 samples at 50 Hz are on the grid) from
    a start 20 times too long; another effect's start is returned unchanged."""
    from panto.identification.diagnosis.augmentations import AugmentedStructure
    from panto.identification.diagnosis.refit import LAG_GRID, located_lag

    _, _, model, _, search = stopped
    plain = fit_nominal(model.structure, model.free, _run(1, lag=0.0)).parameters
    setting = {"input": "u", "time_constant_s": 2.4}
    structure = AugmentedStructure(model.structure, "actuator_lag", search.roles, setting)
    start = {**plain, "actuator_lag:u": 2.4}
    located = located_lag(structure, start, search.train)
    h = search.train.sample_period
    assert located["actuator_lag:u"] in [k * h for k in LAG_GRID]
    assert abs(located["actuator_lag:u"] - LAG) <= 2 * h
    assert _cost((None, Model(structure, located, ())), search) < \
        _cost((None, Model(structure, start, ())), search)
    other = AugmentedStructure(model.structure, "offset", search.roles,
                               {"output": "y", "coefficient": 0.0, "scale": 1.0})
    assert located_lag(other, dict(plain), search.train) == dict(plain)
