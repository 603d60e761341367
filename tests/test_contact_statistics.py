"""The contact-force distribution as withheld evidence for a contact loss
(identification/diagnosis/contact_statistics.py): a clipped force whose bounces land at other
instants than the measured ones passes; where the head never leaves the wire, or the candidate
keeps pulling, it does not."""
from __future__ import annotations

import numpy as np
import pytest

from panto.identification.diagnosis.contact_statistics import (QUANTILES, quantile_misfit,
                                                               statistics_evidence)
from panto.identification.estimation.base import IdentificationData, fit_percent

RATE = 100.0


def _force(mean: float, seconds: float = 40.0, phase: float = 0.0, seed: int = 1) -> np.ndarray:
    t = np.arange(int(seconds * RATE)) / RATE
    rng = np.random.default_rng(seed)
    wave = sum(a * np.sin(2 * np.pi * f * t + phase * k + p) for k, (a, f, p) in enumerate(
        zip(rng.uniform(20, 60, 6), rng.uniform(0.5, 8.0, 6), rng.uniform(0, 6.28, 6))))
    return mean + wave


def _data(measured: np.ndarray) -> IdentificationData:
    n = len(measured)
    return IdentificationData(np.arange(n) / RATE, np.zeros((n, 1)), measured[:, None], ("eta",),
                              ("F_c",))


def test_the_quantile_misfit_is_zero_for_the_same_distribution_and_scales_with_a_shift():
    x = _force(100.0)
    rng = np.random.default_rng(4)
    shuffled = rng.permutation(x)  # same values, other instants: no sample-by-sample fit
    assert quantile_misfit(x, shuffled, np.std(x)) == pytest.approx(0.0, abs=1e-12)
    assert fit_percent(x, shuffled) < 0.0
    assert quantile_misfit(x, x + 0.5 * np.std(x), np.std(x)) == pytest.approx(0.5, rel=1e-12)
    assert len(QUANTILES) >= 5


def test_a_flying_head_passes_on_its_force_distribution_though_it_fits_worse_sample_by_sample():
    rng = np.random.default_rng(2)
    bilateral = _force(60.0)                       # the nominal: it pulls the head to the wire
    measured = np.maximum(bilateral, 0.0) + rng.normal(0.0, 2.0, len(bilateral))
    # the candidate loses contact as the plant does, but its landings drift in time
    candidate = np.maximum(_force(60.0, phase=0.3), 0.0)
    data = _data(measured)
    assert fit_percent(measured, candidate) < fit_percent(measured, bilateral)
    evidence = statistics_evidence(data, bilateral[:, None], candidate[:, None], "F_c", 4)
    assert evidence["accepted"], evidence["reason"]
    assert evidence["after"] <= 0.5 * evidence["before"]
    assert all(after < before for before, after in evidence["folds"])


def test_no_pass_where_the_head_never_leaves_the_wire_or_the_candidate_still_pulls():
    rng = np.random.default_rng(3)
    pressed = _force(400.0)                         # never below zero: nothing to lose
    measured = pressed + rng.normal(0.0, 2.0, len(pressed))
    same = np.maximum(pressed, 0.0)
    assert not statistics_evidence(_data(measured), pressed[:, None], same[:, None], "F_c",
                                   4)["accepted"]
    bilateral = _force(60.0)
    flying = np.maximum(bilateral, 0.0) + rng.normal(0.0, 2.0, len(bilateral))
    still_pulling = _force(60.0, phase=0.3)         # a candidate that does not clip
    assert not statistics_evidence(_data(flying), bilateral[:, None], still_pulling[:, None],
                                   "F_c", 4)["accepted"]
