"""The closed loop of thesis section 5.5 (identify from an APRBS run, design run 2 there, run it,
re-identify from both): the uncertainty shrinks as the design predicted (issue 19).

The plant is written apart from the fit: the three-mass oscillator as the design sees it
(:class:`LinearisedPantograph`: Markov parameters of the exact first-order-hold discretisation,
FFT convolution, the bellow's pressure lag), at true values away from the structure's nominal
ones, plus white force-sensor noise. The fit simulates the same structure by its own state
recursion (:class:`OscillatorStructure`) on the measured pressure. The structure represents the
plant exactly, so what is left between predicted and achieved standard deviation is

* the point: the prediction linearises at the run-1 estimate, the achieved std at the joint
  estimate (both within about 2 % of the truth here, so sensitivities differ by a few %);
* the noise level: the prediction uses the run-1 residual variance, estimated from 500 samples
  (relative error of the std about ``1/sqrt(2 N)`` = 3 %);
* the product's covariance allows coloured noise (a Bartlett-tapered residual autocovariance of
  a few lags, each sample autocorrelation about ``+-1/sqrt(N)`` = 4.5 %).

Together these stay well inside a factor 1.5 either way, the tolerance used here. The std of
the parameters must shrink by the predicted factor; a repeat of the APRBS run is the control:
it shrinks every std by exactly :math:`\\sqrt 2` (twice the information), well short of what the
design predicts, so the designed-run check fails for it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from panto.identification.design.closed_loop import (ClosedLoopOptions, closed_loop_experiment,
                                                     predicted_least_squares_std)
from panto.identification.design.closed_loop_runs import JointExperiments, join_records
from panto.identification.design.constraints import RigInputConstraints
from panto.identification.design.pantograph import DesignOptions, model_inputs
from panto.identification.design.pantograph_sensitivity import LinearisedPantograph
from panto.identification.estimation.base import IdentificationData
from panto.identification.structures.oscillators import OscillatorStructure

CONSTRAINTS = RigInputConstraints()
FACTOR = 1.5  # tolerance on predicted vs achieved std (module notes)
NOISE = {"F_c": 0.5, "y_cb": 1e-3}  # white sensor noise [N], [m]
TRUTH = OscillatorStructure(3).nominal() | {"m1": 7.2, "k2": 9920.0, "c1": 169.0,
                                            "p_gain": 110.0}


class Plant:
    """The three-mass oscillator at :data:`TRUTH` with white noise (module notes)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, name, motor, demand, constraints):
        model = LinearisedPantograph("three-mass", TRUTH, outputs=tuple(NOISE),
                                     length=len(motor), pressure_lag=constraints.pressure_lag,
                                     operating_point=constraints.operating_point(),
                                     sample_period=constraints.sample_period)
        y = model.simulate(model_inputs(motor, demand, constraints))
        y = y + self.rng.normal(size=y.shape) * np.array(list(NOISE.values()))
        pressure = constraints.pressure_lag.apply(demand, constraints.sample_period,
                                                  constraints.pressure_start)
        inputs = np.column_stack([constraints.motor_zero_height + motor, pressure])
        return IdentificationData(np.arange(len(motor)) * constraints.sample_period, inputs, y,
                                  ("eta", "p"), tuple(NOISE), source=name)


def _loop(next_run: str, outputs=("F_c",)):
    # the repeat does not play the design, it only needs the APRBS run's information: a token GA
    ga = DesignOptions(population=16, generations=10) if next_run == "designed" else \
        DesignOptions(population=4, generations=1)
    options = ClosedLoopOptions(structure="three-mass", duration=10.0, next_run=next_run,
                                outputs=outputs, design=ga)
    return closed_loop_experiment(Plant(1), options=options, constraints=CONSTRAINTS,
                                  truth=TRUTH)


@pytest.fixture(scope="module")
def designed():
    return _loop("designed")


@pytest.fixture(scope="module")
def repeated():
    return _loop("repeat")


def _within(achieved: float, predicted: float) -> bool:
    return predicted / FACTOR <= achieved <= predicted * FACTOR


def test_achieved_std_is_the_predicted_one(designed):
    """After run 1 and after runs 1 + 2 every parameter's std is the predicted one within the
    factor; one output: the prediction is the Cramer-Rao bound of the design's Fisher
    information, and the estimates lie within 4 std of the truth."""
    assert designed.first.success and designed.joint.success
    for p in designed.parameters:
        assert _within(p.std_first, p.predicted_std_first), p
        assert _within(p.std_joint, p.predicted_std_joint), p
        assert p.predicted_std_joint == pytest.approx(p.bound_std_joint, rel=1e-6)
        assert abs(p.estimate_joint - p.truth) < 4 * p.std_joint, p


def test_the_std_shrinks_by_the_predicted_factor_and_a_repeat_does_not(designed, repeated):
    """The parameter the design helps most shrinks by the predicted factor (within the
    tolerance); the repeat's predicted shrink is sqrt 2 for every parameter, achieved too, and
    falls short of the designed prediction: the check above fails for the repeat."""
    best = max(designed.parameters, key=lambda p: p.predicted_shrink)
    assert _within(best.achieved_shrink, best.predicted_shrink), best
    assert all(p.predicted_shrink > 1.0 for p in designed.parameters)
    for p in repeated.parameters:
        assert p.predicted_shrink == pytest.approx(math.sqrt(2.0), rel=1e-9)
        assert _within(p.achieved_shrink, math.sqrt(2.0)), p
    control = repeated.outcome(best.name)
    assert not _within(control.achieved_shrink, best.predicted_shrink), (best, control)


def test_two_outputs_the_fit_weighting_is_predicted():
    """Force and cross-bar height fitted together: the product's fit weights each output by its
    spread, not its noise, so it stays above the Cramer-Rao bound; the prediction for that
    estimator (:func:`predicted_least_squares_std`) is what it achieves."""
    result = _loop("repeat", outputs=("F_c", "y_cb"))
    for p in result.parameters:
        assert _within(p.std_first, p.predicted_std_first), p
        assert _within(p.std_joint, p.predicted_std_joint), p
        assert p.predicted_std_joint >= p.bound_std_joint * (1 - 1e-9)
    assert any(p.predicted_std_joint > 1.3 * p.bound_std_joint for p in result.parameters)


def test_joint_records_are_simulated_apart():
    """Two records joined: the joint simulation is each record's own, stacked (a record
    simulated from its own rest start, not continuing the first)."""
    structure = OscillatorStructure(2, outputs=("F_c",))
    records = []
    for amplitude in (0.02, -0.05):
        t = np.arange(200) * 0.02
        eta = 2.0 + amplitude * np.sin(2 * np.pi * t)
        inputs = np.column_stack([eta, np.full_like(t, 4.0 + amplitude)])
        records.append(IdentificationData(t, inputs, np.zeros((200, 1)), ("eta", "p"), ("F_c",)))
    joined, lengths = join_records(records)
    apart = np.vstack([structure.simulate({}, r) for r in records])
    together = JointExperiments(structure, lengths).simulate({}, joined)
    np.testing.assert_allclose(together, apart, rtol=1e-12, atol=1e-12)
    assert not np.allclose(structure.simulate({}, joined), apart)


def test_prediction_for_one_output_is_the_cramer_rao_bound():
    """With one output the least-squares sandwich equals the inverse Fisher information of the
    design model (two computations: sensitivities here, ``fisher`` there)."""
    model = LinearisedPantograph("two-mass", free=("m1", "k1", "c1"), outputs=("F_c",),
                                 length=300, pressure_lag=CONSTRAINTS.pressure_lag)
    t = np.arange(300) * 0.02
    motor, demand = 0.03 * np.sin(2 * np.pi * 1.3 * t), 4.0 + 0.2 * (t > 2.0)
    std = predicted_least_squares_std(model, [(motor, demand)], CONSTRAINTS, [0.25])
    fisher = model.fisher(model_inputs(motor, demand, CONSTRAINTS), [0.25])
    np.testing.assert_allclose(std, np.sqrt(np.diag(np.linalg.inv(fisher))), rtol=1e-9)
