"""Levenberg-Marquardt with Broyden-updated Jacobians (``fit_least_squares(broyden=k)``).

Two independent paths must reach the same optimum: the full finite-difference Jacobian every
iteration (the default) and the reused, rank-1 updated one; and the paired trials on an
executor must take exactly the steps of the sequential trials.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from panto.identification.estimation.base import IdentificationData
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.physical import PhysicalLinear, PhysicalNonlinear

TRUTH = {"c1": 300.0, "k_c": 19000.0, "k_p": 250.0, "m_c": 6.5}
START = {"c1": 200.0, "k_c": 25000.0, "k_p": 300.0, "m_c": 5.0}
NOISE = np.array([1.0, 5e-4])  # F_c [N], y_cb [m]


def _data(structure, duration: float, seed: int = 4) -> IdentificationData:
    """Outputs of `structure` at :data:`TRUTH` plus white noise on a two-input excitation."""
    time = np.arange(0.0, duration, 0.02)
    eta = 2.0 + 0.02 * (np.sin(2 * np.pi * 0.7 * time) + 0.5 * np.sin(2 * np.pi * 3.1 * time))
    p = 4.0 + 0.5 * np.sin(2 * np.pi * 0.23 * time + 0.4)
    base = IdentificationData(time, np.column_stack([eta, p]), np.zeros((len(time), 2)),
                              ("eta", "p"), ("F_c", "y_cb"), source="synthetic")
    clean = structure.simulate(TRUTH, base)
    noisy = clean + NOISE * np.random.default_rng(seed).standard_normal(clean.shape)
    return IdentificationData(time, base.inputs, noisy, base.input_names, base.output_names)


def _same_optimum(updated, full, sigmas: float) -> None:
    """Both converged, at the same cost, with parameters far inside their uncertainty, and
    within `sigmas` standard deviations of the truth."""
    assert updated.success and full.success, (updated.message, full.message)
    assert updated.details["cost"] == pytest.approx(full.details["cost"], rel=1e-5)
    for name in TRUTH:
        assert abs(updated.parameters[name] - full.parameters[name]) < 0.05 * full.std[name], name
        assert abs(updated.parameters[name] - TRUTH[name]) < sigmas * updated.std[name], name


def test_broyden_updates_reach_the_full_jacobian_optimum():
    structure = PhysicalLinear()
    data = _data(structure, 40.0)
    full = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START)
    updated = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START, broyden=10)
    _same_optimum(updated, full, 1.96)
    assert full.details["iterations"] < updated.details["iterations"]  # cheaper, more of them


def test_paired_trials_take_the_sequential_steps():
    """With an executor the trials go in pairs (damping and 4 x damping): the same path."""
    structure = PhysicalLinear()
    data = _data(structure, 20.0, seed=5)
    sequential = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START, broyden=5)
    with ThreadPoolExecutor(2) as pool:
        paired = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START, broyden=5,
                                   executor=pool)
    assert paired.details["iterations"] == sequential.details["iterations"]
    assert paired.details["cost"] == sequential.details["cost"]
    assert paired.parameters == sequential.parameters
    assert paired.n_evaluations >= sequential.n_evaluations  # the unused second trials


def test_the_default_is_a_fresh_jacobian_every_iteration():
    """Structures without ``broyden_updates`` keep the plain method: broyden=0 is the same fit."""
    structure = PhysicalLinear()
    data = _data(structure, 20.0, seed=6)
    default = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START)
    plain = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START, broyden=0)
    assert default.parameters == plain.parameters
    assert default.n_evaluations == plain.n_evaluations


def test_fmu_in_the_loop_with_updates_matches_the_full_jacobian():
    """The nonlinear structure's own default (Broyden updates) against full Jacobians."""
    structure = PhysicalNonlinear()
    assert structure.broyden_updates > 0
    data = _data(structure, 12.0, seed=7)
    updated = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START)
    full = fit_least_squares(structure, data, free=tuple(TRUTH), initial=START, broyden=0)
    _same_optimum(updated, full, 4.0)  # 4 parameters, one noise record: not the 95 % band
    assert updated.fit["F_c"] == pytest.approx(full.fit["F_c"], abs=0.01)
