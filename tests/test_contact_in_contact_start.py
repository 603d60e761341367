"""A contact loss refitted from the nominal fitted to the samples in contact only
(identification/diagnosis/refit.py ``_in_contact_refit``). A nominal fitted to a flying head is
bent by the flights its bilateral contact cannot follow; the unilateral refit from there, and
from the defaults, validated worse on the force than the nominal and was rejected (seen held-out
two-mass/contact_loss/1598, benchmarks/effect_plants.py: the head off the wire on 22 % of the
samples, `unexplained`). Since session 44 the nominal's global fit matches the adequacy's black
box and the first refit from it passes (y_cb 79.4 %); the in-contact start now runs after a
pass too and reaches 90.7 %."""
from __future__ import annotations

import pytest
from fixtures.excitations import load_benchmark

from panto.identification.diagnosis import refit as refit_module
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose


def _diagnosis():
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "contact_loss", 1598, quick=True),
                              scored=False)
    return diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                    options=DiagnosisOptions(candidates=("contact_loss",), discovery=False,
                                             challenge=False, workers=1))


@pytest.fixture(scope="module")
def with_start():
    """The diagnosis with the in-contact start (both tests read it; about 7 s)."""
    return _diagnosis()


def test_a_flying_head_is_named_from_the_in_contact_start(with_start):
    result = with_start
    assert result.effects == ("contact_loss",), result.summary
    # every output validates better, the cross bar and the head by tens of points (measured:
    # F_c 26.4 -> 31.3 %, y_cb 32.1 -> 90.7 %, xi -10.6 -> 88.4 %)
    gains = {o: result.fit_after[o] - result.fit_before[o] for o in result.fit_before}
    assert min(gains.values()) > 0.0 and gains["y_cb"] > 30.0 and gains["xi"] > 30.0, gains


def test_without_the_in_contact_start_the_same_run_is_never_diagnosed_better(monkeypatch,
                                                                             with_start):
    """The control: whether the other starts reach the unilateral basin depends on the machine's
    rounding (measured on this case: with NumPy's AVX-512 loops, session 43's machine, and on
    session 42's machine `unexplained` without the in-contact start; with them switched off,
    ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL"``, the same `contact_loss` as with it, F_c
    30.9 %, y_cb 79.4 %, xi 76.7 %). What holds on every machine: without the start no output
    validates better, and the verdict names no other effect."""
    def refused(*arguments, **keywords):
        raise refit_module.IdentificationError("in-contact start switched off for this test")

    monkeypatch.setattr(refit_module, "_in_contact_refit", refused)
    without = _diagnosis()
    assert without.effects in ((), ("contact_loss",)), without.summary
    assert all(without.fit_after[o] <= with_start.fit_after[o] + 1e-9 for o in without.fit_after), \
        (without.fit_after, with_start.fit_after)


def test_a_nominal_bent_until_it_never_pulls_still_gets_the_contact_loss_tried():
    """Seen held-out two-mass/contact_loss/5168: the head off the wire on a good part of the run
    (the training force below zero on 4 % of the samples: the sensor's noise about zero while
    it flies), the nominal bent until its force never goes below zero, so the ranking's regressor
    ``max(F, 0) - F`` is zero and, before session 49, contact loss was never tried
    (`unexplained`). Offered on the measured force's floor (``measured F < 0``), refitted from
    the in-contact start and judged on the withheld run: named, the cross bar's fit from 0.0 to
    72.6 % (measured)."""
    plants, harness = load_benchmark("effect_plants"), load_benchmark("diagnosis_families")
    case = plants.effect_case(plants.draw_spec("two-mass", "contact_loss", 5168, quick=True),
                              scored=False)
    result = diagnose(harness.to_data(case, 0), harness.to_data(case, 1), structure="two-mass",
                      options=DiagnosisOptions(candidates=("contact_loss",), discovery=False,
                                               challenge=False, workers=1))
    tried = [t for r in result.rounds for t in r["tried"]]
    assert [t["variant"] for t in tried][:1] == ["measured F < 0"], tried
    assert result.effects == ("contact_loss",), result.summary
    assert result.fit_after["y_cb"] > result.fit_before["y_cb"] + 50.0, result.summary


def test_the_measured_floor_offers_contact_loss_only_where_the_force_goes_below_zero():
    """The trigger alone (pipeline._predicted_contact_loss): a training force below zero on 1 %
    of the samples or more offers the candidate where the model never pulls; a pressed head's
    force (never below zero) and a model already pulling keep their behaviour."""
    import numpy as np

    from panto.identification.diagnosis.effects import SignalRoles
    from panto.identification.diagnosis.pipeline import _predicted_contact_loss
    from panto.identification.estimation.base import IdentificationData

    n = 1000
    roles = SignalRoles(force="F_c")

    def run(force):
        return IdentificationData(np.arange(n) / 100.0, np.zeros((n, 1)), force[:, None],
                                  ("eta",), ("F_c",))

    pressed = 100.0 + np.sin(np.arange(n) / 10.0)
    flying = pressed.copy()
    flying[:15] = -0.5                               # 1.5 % of the samples below zero
    never_pulls = pressed[:, None]
    offered = _predicted_contact_loss([], ["contact_loss"], roles, run(flying), run(pressed),
                                      never_pulls)
    assert [c["variant"] for c in offered] == ["measured F < 0"]
    assert _predicted_contact_loss([], ["contact_loss"], roles, run(pressed), run(pressed),
                                   never_pulls) == []
    pulling = (pressed - 100.5)[:, None]
    assert [c["variant"] for c in _predicted_contact_loss(
        [], ["contact_loss"], roles, run(pressed), run(pressed), pulling)] == ["predicted F < 0"]
    assert _predicted_contact_loss([], [], roles, run(flying), run(pressed), never_pulls) == []
