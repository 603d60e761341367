"""The size test of an effect with several magnitude parameters (identification/diagnosis/
support.py ``_significance``): the largest single ``|theta| / sigma``, or where larger the joint
Wald test of the magnitudes with a standard deviation, as the same two-sided tail."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from panto.identification.diagnosis.support import _significance


class _Oscillator:
    """Stands in for an augmented oscillator: its per-mass friction forces are the magnitudes."""

    magnitude_parameters = ("F_f1", "F_f2", "F_f3")
    effect_parameters = magnitude_parameters


def _covariance(std: dict[str, float], correlation: float) -> dict:
    names = ("k1", "F_f1", "F_f2", "F_f3")
    matrix = np.diag([1.0] + [std[n] ** 2 if std[n] > 0 else math.nan for n in names[1:]])
    matrix[1, 2] = matrix[2, 1] = correlation * std["F_f1"] * std["F_f2"]
    return {"names": names, "matrix": matrix}


def test_two_forces_trading_against_each_other_are_jointly_far_from_zero():
    """Each force at 2 sigma, correlation -0.9 (what one can gain the other loses), the third
    at its zero bound (no deviation): the joint statistic is the analytic one,
    ``z' C^-1 z = (4 + 4 + 2 * 0.9 * 4) / (1 - 0.81)`` on 2 degrees of freedom, far beyond 3."""
    own = {"F_f1": 20.0, "F_f2": 4.0, "F_f3": 0.0}
    std = {"F_f1": 10.0, "F_f2": 2.0, "F_f3": math.nan}
    z = _significance("coulomb_friction", _Oscillator(), own, std, _covariance(std, -0.9))
    wald = (4 + 4 + 2 * 0.9 * 4) / (1 - 0.81)
    assert z == pytest.approx(stats.norm.isf(0.5 * stats.chi2.sf(wald, 2)), rel=1e-9)
    assert z > 5


def test_an_undetermined_magnitude_is_left_out_of_the_joint_test():
    """The least-squares uncertainty gives a direction the data do not determine an infinite
    deviation: that magnitude is left out, the other two are tested jointly as without it."""
    own = {"F_f1": 20.0, "F_f2": 4.0, "F_f3": 7.0}
    std = {"F_f1": 10.0, "F_f2": 2.0, "F_f3": math.nan}
    reference = _significance("coulomb_friction", _Oscillator(), own, std, _covariance(std, -0.9))
    covariance = _covariance(std, -0.9)
    covariance["matrix"][3, 3] = math.inf
    undetermined = {**std, "F_f3": math.inf}
    assert _significance("coulomb_friction", _Oscillator(), own, undetermined,
                         covariance) == pytest.approx(reference, rel=1e-12)
    assert reference > 5


def test_the_joint_test_never_lowers_the_single_ratio_and_one_magnitude_is_unchanged():
    """Positively correlated forces at 2 sigma each carry no more evidence together than one
    (the joint tail on 2 degrees of freedom is below the single ratio): the single ratio stands;
    without a covariance, or with one magnitude, it is the single ratio as before."""
    own = {"F_f1": 20.0, "F_f2": 4.0, "F_f3": 0.0}
    std = {"F_f1": 10.0, "F_f2": 2.0, "F_f3": math.nan}
    assert _significance("coulomb_friction", _Oscillator(), own, std,
                         _covariance(std, 0.95)) == pytest.approx(2.0)
    assert _significance("coulomb_friction", _Oscillator(), own, std) == pytest.approx(2.0)

    class _One:
        magnitude_parameters = ("F_f1",)
        effect_parameters = ("F_f1",)

    assert _significance("coulomb_friction", _One(), {"F_f1": 20.0}, {"F_f1": 10.0},
                         _covariance(std, -0.9)) == pytest.approx(2.0)
