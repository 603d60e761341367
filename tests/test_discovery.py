"""Discovery of a term the effect vocabulary lacks (issue 24): plants written here, a linear
second-order system whose measured output passes through a sign-blind sensor, a backlash (play)
or gets a cubic term; the nominal is the linear model; the hypothesis must name the term's family
and gain on a withheld run, and clean data must not produce one."""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from panto.identification.diagnosis.discovery import (DiscoveryOptions, Hypothesis, Signal, Term,
                                                      discover, low_pass, play, with_term)
from panto.identification.estimation.base import IdentificationData, ModelStructure, fit_percent
from panto.identification.estimation.least_squares import fit_least_squares

RATE = 50.0
TRUTH = {"K": 1.0, "w": 6.0, "z": 0.25, "y0": 0.0}
FREE = ("K", "w", "z", "y0")


class _SecondOrder(ModelStructure):
    """``y = y0 + K w^2 / (s^2 + 2 z w s + w^2) u``, Tustin-discretised."""

    name = "second-order"
    input_names = ("u",)
    output_names = ("y",)
    parameter_names = FREE

    def nominal(self):
        return dict(TRUTH)

    def bounds(self):
        return {"K": (-100.0, 100.0), "w": (0.1, 100.0), "z": (0.01, 5.0), "y0": (-100.0, 100.0)}

    def simulate(self, parameters, data):
        p = {**self.nominal(), **parameters}
        b, a = signal.bilinear([p["K"] * p["w"] ** 2], [1.0, 2 * p["z"] * p["w"], p["w"] ** 2],
                               fs=1.0 / data.sample_period)
        return (signal.lfilter(b, a, data.inputs[:, 0]) + p["y0"])[:, None]


PLANT = _SecondOrder()


def _run(seed: int, effect, mean=(0.0, 0.0), n: int = 1500) -> IdentificationData:
    """Filtered-noise input (its mean `mean[0]` in the first half, `mean[1]` after); measured
    output ``effect(y)`` plus 1 % white noise."""
    rng = np.random.default_rng(seed)
    b, a = signal.butter(2, 0.08)
    u = 3.0 * signal.lfilter(b, a, rng.normal(size=n)) + np.where(np.arange(n) < n // 2, *mean)
    time = np.arange(n) / RATE
    y = PLANT.simulate(TRUTH, IdentificationData(time, u[:, None], np.zeros((n, 1)), ("u",),
                                                 ("y",)))[:, 0]
    measured = effect(y)
    measured = measured + 0.01 * np.std(measured) * rng.normal(size=n)
    return IdentificationData(time, u[:, None], measured[:, None], ("u",), ("y",))


def _nominal(data: IdentificationData) -> dict[str, float]:
    start = {**TRUTH, "z": 0.4, "w": 5.0}
    return dict(fit_least_squares(PLANT, data, free=FREE, initial=start).parameters)


def test_play_operator_and_low_pass_follow_their_definitions():
    t = np.linspace(0.0, 4 * np.pi, 2001)
    s = np.sin(t)
    z = play(s, 0.2)
    # after the first peak it holds for 2 r of travel at each reversal (|s| > 1 - 2 r), and
    # between the reversals it follows the input lagging by exactly the radius
    moving = (t > np.pi / 2) & (np.abs(s) < 1.0 - 2 * 0.2)
    assert np.allclose(np.abs(z - s)[moving], 0.2, atol=1e-12)
    assert z.max() == pytest.approx(0.8, abs=1e-6) and z[t > np.pi].min() == pytest.approx(-0.8,
                                                                                           abs=1e-6)
    step = low_pass(np.r_[0.0, np.ones(999)], 0.5, 0.01)
    assert step[50] == pytest.approx(1.0 - np.exp(-0.5 / 0.5), rel=1e-12)  # 50 steps of 0.01 s


def test_the_compiled_play_operator_is_the_python_loop_bit_for_bit(monkeypatch):
    """The C play operator against the loop it replaces (the same comparisons, so the same
    values): random walks, a zero and a wide radius, a NaN sample, one and no samples; and the
    loop runs where the kernel is switched off."""
    from panto.identification.diagnosis import discovery

    assert discovery._play_kernel() is not None  # gcc is part of the set-up: the kernel builds
    rng = np.random.default_rng(7)
    walk = np.cumsum(rng.normal(size=3000))
    gappy = walk.copy()
    gappy[1234] = np.nan
    for s in (walk, gappy, walk[:1], walk[:0]):
        for radius in (0.0, 0.37, 50.0):
            assert np.array_equal(play(s, radius), discovery.play_loop(s, radius),
                                  equal_nan=True), (len(s), radius)
    called = []
    monkeypatch.setenv("PANTO_PLAY_KERNEL", "0")
    monkeypatch.setattr(discovery, "play_loop", lambda s, r: called.append(r) or s)
    play(walk, 0.5)
    assert called == [0.5]


def test_term_structure_adds_the_term_to_the_nominal_simulation():
    data = _run(3, lambda y: y)
    term = Term("cube", (Signal("output", "y"),))
    model = with_term(PLANT, [term], "y", [0.3])
    y = PLANT.simulate(TRUTH, data)[:, 0]
    assert np.allclose(model.simulate(TRUTH, data)[:, 0], y + 0.3 * y ** 3)
    assert model.parameter_names == FREE + ("discovered_theta_1",)


@pytest.mark.parametrize("case", ["sign_blind_sensor", "sign_blind_sensor_distorted_nominal",
                                  "backlash", "cubic"])
def test_the_hidden_term_is_named_and_gains_on_the_withheld_run(case):
    effect, family, mean = {
        # speed-like signal through |.|: positive in the first half, crossing zero after
        "sign_blind_sensor": (np.abs, "abs", (2.0, 0.5)),
        "sign_blind_sensor_distorted_nominal": (np.abs, "abs", (2.0, 0.5)),
        "backlash": (lambda y: play(y, 0.07 * np.ptp(y)), "play", (0.0, 0.0)),
        "cubic": (lambda y: y + 0.15 * y ** 3, "cube", (0.0, 0.0)),
    }[case]
    train, validation = _run(1, effect, mean), _run(2, effect, mean)
    # the sign-blind sensor is linear while the signal stays positive: the nominal is fitted on
    # that clean first half; the others on the whole training run, as the diagnosis fits them
    # (the sensor then distorts the nominal: its zero sits at a kink |y - c| of the library)
    fitted_on = train.segment(0.0, train.time[len(train) // 2]) if case == "sign_blind_sensor" \
        else train
    nominal = _nominal(fitted_on)
    hypothesis = discover(PLANT, nominal, FREE, train, validation)
    assert isinstance(hypothesis, Hypothesis)
    assert hypothesis.families[0] == family, hypothesis.term
    # the term with the right family reproduces the measured characteristic up to the
    # discretisation of its width: most of the validation gap must close
    assert hypothesis.gain > 5.0 and hypothesis.gap_closed > 0.6, hypothesis.to_dict()
    truth_fit = fit_percent(validation.outputs[:, 0],
                            effect(PLANT.simulate(TRUTH, validation)[:, 0]))
    assert hypothesis.fit_validation_after <= truth_fit + 1.0  # no better than the plant itself
    json.dumps(hypothesis.to_dict())


def test_clean_data_gives_no_discovery():
    train, validation = _run(1, lambda y: y), _run(2, lambda y: y)
    hypothesis = discover(PLANT, _nominal(train), FREE, train, validation,
                          options=DiscoveryOptions(candidates=2))
    assert hypothesis is None or hypothesis.gain < 0.2


def test_lasso_bic_solver_ranks_the_cubic_term_first():
    effect = lambda y: y + 0.15 * y ** 3  # noqa: E731
    train, validation = _run(1, effect), _run(2, effect)
    hypothesis = discover(PLANT, _nominal(train), FREE, train, validation,
                          options=DiscoveryOptions(solver="lasso-bic", candidates=1))
    assert hypothesis is not None and hypothesis.families[0] == "cube"
    assert hypothesis.ranking[0][1] == "y^3 - y"


def test_a_refitted_kink_level_finds_a_sensor_zero_between_the_quantiles():
    # A sensor reads r + |y - r| (reflected below r): the kink term |y - c| - y with theta = 1
    # and c = r reproduces it exactly with the nominal unchanged. r lies between the library's
    # quantiles; with the level chosen on a grid the refit lands on r and closes the gap to the
    # noise.
    mean = (1.0, 1.0)
    reference = 0.37  # between quantiles of y on this run
    effect = lambda y: reference + np.abs(y - reference)  # noqa: E731
    train, validation = _run(1, effect, mean), _run(2, effect, mean)
    nominal = dict(TRUTH)  # the sensor is the only discrepancy
    fixed = DiscoveryOptions(families=("abs",), delays=(), derivatives=False, products=False,
                             kink_quantiles=(0.1, 0.25, 0.5), candidates=3)
    free = DiscoveryOptions(**{**{f: getattr(fixed, f) for f in
                                  ("families", "delays", "derivatives", "products",
                                   "kink_quantiles", "candidates")}, "level_grid": 200})
    y = PLANT.simulate(nominal, train)[:, 0]
    assert min(abs(np.quantile(y, q) - reference) for q in fixed.kink_quantiles) > 0.05
    at_quantiles = discover(PLANT, nominal, FREE, train, validation, options=fixed)
    refitted = discover(PLANT, nominal, FREE, train, validation, options=free)
    assert refitted is not None and refitted.families == ("abs",)
    level = float(refitted.term.split("|y - ")[1].split("|")[0])  # the formula's kink
    assert level == pytest.approx(reference, abs=0.03)
    assert refitted.coefficients[0] == pytest.approx(1.0, abs=0.05)
    truth_fit = fit_percent(validation.outputs[:, 0],
                            effect(PLANT.simulate(TRUTH, validation)[:, 0]))
    assert refitted.fit_validation_after > truth_fit - 0.5
    assert at_quantiles is None or refitted.gain > at_quantiles.gain


def test_a_hypothesis_stopped_on_its_budget_is_continued_to_the_converged_optimum():
    """With 12 simulations per refit the cubic term's refit stops on its budget far from its
    optimum; the chosen hypothesis is then continued (three times the budget) from where it
    stopped and must land where a refit with the default 600 simulations converges."""
    effect = lambda y: y + 0.15 * y ** 3  # noqa: E731
    train, validation = _run(1, effect), _run(2, effect)
    nominal = _nominal(train)
    options = {"candidates": 1, "families": ("cube",)}
    lines: list[str] = []
    short = discover(PLANT, nominal, FREE, train, validation, progress=lines.append,
                     options=DiscoveryOptions(max_evaluations=12, **options))
    full = discover(PLANT, nominal, FREE, train, validation, options=DiscoveryOptions(**options))
    assert short is not None and full is not None and full.message.startswith("converged")
    stopped = [line for line in lines if line.startswith("discovery: refit with y^3 - y on")]
    assert stopped and "maximum of 12 model evaluations" in stopped[0], lines
    assert any(line.startswith("discovery: continued y^3 - y on y") for line in lines), lines
    assert float(stopped[0].split("-> ")[1].split(" %")[0]) < full.fit_validation_after - 5.0
    assert short.term == full.term and short.message.startswith("converged")
    assert short.coefficients[0] == pytest.approx(full.coefficients[0], rel=1e-3)
    assert short.fit_validation_after == pytest.approx(full.fit_validation_after, abs=0.01)
