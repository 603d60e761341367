"""A refit that stopped on its budget is continued before two candidates the withheld run cannot
tell apart are ranked by their training dBIC (identification/diagnosis/refit.py continue_refit,
choice.settle_ties, choice.choose_converged). Plant written here: a second-order system behind a first-order actuator
lag (discretised by SciPy with a first-order hold, not by the diagnosis' own filter), nominal
``linear-2``."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis.nominal import fit_nominal
from panto.identification.diagnosis.pipeline import DiagnosisOptions
from panto.identification.diagnosis.refit import Model, Search, continue_refit, try_candidate
from panto.identification.diagnosis.support import build_structure, default_roles, residuals
from panto.identification.estimation.base import IdentificationData

RATE = 50.0
LAG = 0.12  # s


def _run(seed: int, n: int = 1500) -> IdentificationData:
    rng = np.random.default_rng(seed)
    u = 2.0 * signal.lfilter(*signal.butter(2, 0.15), rng.normal(size=n))
    lagged = signal.dlsim(signal.cont2discrete(([1.0], [LAG, 1.0]), 1.0 / RATE, method="foh"),
                          u)[1][:, 0]
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
    from panto.identification.diagnosis.choice import choose_converged

    candidate, entry, model, current, search = stopped
    assert entry[0].accepted and "maximum" in entry[0].message
    trials, chosen = choose_converged([entry], [candidate], model, current, search)
    assert chosen is trials[0] and chosen is not entry
    assert chosen[0].continued and chosen[0].message.startswith("converged")
    assert _cost(chosen, search) < _cost(entry, search)
    assert chosen[1].parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)


def test_a_rejected_trial_is_never_chosen_nor_continued(stopped):
    import dataclasses

    from panto.identification.diagnosis.choice import choose_converged

    candidate, entry, model, current, search = stopped
    rejected = (dataclasses.replace(entry[0], accepted=False),) + tuple(entry[1:])
    trials, chosen = choose_converged([rejected], [candidate], model, current, search)
    assert chosen is None and trials == [rejected]


def test_the_report_says_when_an_accepted_refit_did_not_converge():
    from panto.identification.diagnosis.pipeline import Step
    from panto.identification.diagnosis.report import _not_converged

    step = Step("actuator_lag", "lag", {}, {}, {}, {}, {}, {}, {},
                refit="not converged: maximum of 1200 model evaluations reached")
    assert "maximum of 1200 model evaluations" in _not_converged(step)
    assert _not_converged(Step("actuator_lag", "lag", {}, {}, {}, {}, {}, {}, {},
                               refit="converged: the gradient vanishes")) == ""


def test_a_rejected_refit_that_stopped_on_its_budget_with_a_withheld_gain_is_continued(stopped):
    """Its significance and dBIC were taken where the budget ran out: continued, it is judged at
    its optimum (here the lag the plant has, accepted)."""
    import dataclasses

    from panto.identification.diagnosis.choice import settle_ties

    candidate, entry, model, current, search = stopped
    assert entry[0].improvement > 0.0
    rejected = (dataclasses.replace(entry[0], accepted=False, failed=("stopped short",)),) + \
        tuple(entry[1:])
    [settled] = settle_ties([rejected], [candidate], model, current, search)
    assert settled is not rejected and settled[0].continued and settled[0].accepted
    assert _cost(settled, search) < _cost(rejected, search)
    assert settled[1].parameters["actuator_lag:u"] == pytest.approx(LAG, rel=0.05)


def test_rejected_refits_without_a_withheld_gain_or_converged_are_left_alone(stopped):
    import dataclasses

    from panto.identification.diagnosis.choice import settle_ties

    candidate, entry, model, current, search = stopped
    no_gain = (dataclasses.replace(entry[0], accepted=False, improvement=-0.5),) + \
        tuple(entry[1:])
    assert settle_ties([no_gain], [candidate], model, current, search)[0] is no_gain
    converged = (dataclasses.replace(entry[0], accepted=False,
                                     message="converged: the gradient vanishes"),) + \
        tuple(entry[1:])
    assert settle_ties([converged], [candidate], model, current, search)[0] is converged
