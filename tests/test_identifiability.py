"""Identifiability shown: per-parameter verdicts, sign-respecting intervals, bounds, fixing at prior.

Small structures with known answers: two gains entering only as a product (one direction the
data cannot see), a regression whose weak regressor leaves a positive parameter with a large
relative standard deviation (its ordinary-least-squares standard deviation is the independent
check), and a parameter whose bounds exclude the truth (driven to the bound).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.signal import lfilter

from panto.identification.estimation.base import IdentificationData, ModelStructure
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.estimation.reporting import write_identification
from panto.identification.estimation.uncertainty import Z95


def _data(inputs: np.ndarray, outputs: np.ndarray, dt: float = 0.01) -> IdentificationData:
    n = len(inputs)
    return IdentificationData(np.arange(n) * dt, inputs.reshape(n, -1), outputs.reshape(n, 1),
                              tuple(f"u{i + 1}" for i in range(inputs.reshape(n, -1).shape[1])),
                              ("y",), {"y": "N"})


class ProductLag(ModelStructure):
    """``y`` a first-order lag (time constant ``tau``) of ``K G u``: only ``K G`` is seen."""

    name = "product-lag"
    input_names = ("u1",)
    output_names = ("y",)
    parameter_names = ("K", "G", "tau")

    def nominal(self):
        return {"K": 1.0, "G": 1.0, "tau": 0.5}

    def bounds(self):
        return {"K": (0.01, 100.0), "G": (0.01, 100.0), "tau": (0.01, 10.0)}

    def units(self):
        return {"K": "N/bar", "G": "-", "tau": "s"}

    def simulate(self, parameters, data):
        p = self.nominal() | dict(parameters)
        a = math.exp(-data.sample_period / p["tau"])
        return lfilter([0.0, (1 - a) * p["K"] * p["G"]], [1.0, -a], data.input("u1"))[:, None]


class Regression(ModelStructure):
    """``y = a u1 + b u2``; ``b`` positive (optimised on its logarithm), bounds as given."""

    name = "regression"
    input_names = ("u1", "u2")
    output_names = ("y",)
    parameter_names = ("a", "b")

    def __init__(self, b_bounds=(1e-3, 1e3)):
        self.b_bounds = b_bounds

    def nominal(self):
        return {"a": 1.0, "b": float(np.clip(1.0, *self.b_bounds))}

    def bounds(self):
        return {"a": (-100.0, 100.0), "b": self.b_bounds}

    def units(self):
        return {"a": "N/m", "b": "kg"}

    def simulate(self, parameters, data):
        p = self.nominal() | dict(parameters)
        return (p["a"] * data.input("u1") + p["b"] * data.input("u2"))[:, None]


def _product_data(seed: int = 0) -> IdentificationData:
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], 60), 25)  # a random binary signal, 15 s at 100 Hz
    data = _data(u, np.zeros_like(u))
    clean = ProductLag().simulate({"K": 2.0, "G": 1.5, "tau": 0.3}, data)[:, 0]
    return _data(u, clean + 0.02 * rng.standard_normal(len(u)))


def _regression_data(b: float, weak: float, noise: float, seed: int = 1):
    rng = np.random.default_rng(seed)
    n = 2000
    u1, u2 = rng.standard_normal(n), weak * rng.standard_normal(n)
    y = 3.0 * u1 + b * u2 + noise * rng.standard_normal(n)
    return _data(np.column_stack([u1, u2]), y), u1, u2


def test_a_product_is_not_identifiable_and_one_factor_is_fixed_at_its_prior():
    data = _product_data()
    free = fit_least_squares(ProductLag(), data, free=("K", "G", "tau"))
    estimates = free.estimates
    assert estimates["K"].verdict == estimates["G"].verdict == "not identifiable"
    assert estimates["tau"].verdict == "identifiable"
    # the pair is one group, and the fit claims no precision for either factor
    assert set(estimates["K"].group) == set(estimates["G"].group) == {"K", "G"}
    assert "traded off against G" in estimates["K"].reason
    assert not estimates["K"].relative_std <= 0.5 and not estimates["G"].relative_std <= 0.5
    assert estimates["K"].interval_95[0] >= 0.0
    assert estimates["K"].unit == "N/bar" and estimates["tau"].unit == "s"

    fixed = fit_least_squares(ProductLag(), data, free=("K", "G", "tau"),
                              fix_unidentifiable=True)
    assert fixed.success, fixed.message
    held = [n for n, e in fixed.estimates.items() if e.fixed]
    assert len(held) == 1 and held[0] in ("K", "G")
    other = "G" if held[0] == "K" else "K"
    assert fixed.parameters[held[0]] == ProductLag().nominal()[held[0]]  # exactly its prior
    assert fixed.estimates[held[0]].status.startswith("fixed at prior")
    assert math.isnan(fixed.estimates[held[0]].std)
    assert held[0] in fixed.details["fixed_at_prior"] and "fixed at prior" in fixed.message
    # the product the data do see is recovered, and the free factor is now identifiable
    assert fixed.estimates[other].verdict == "identifiable"
    low, high = fixed.estimates[other].interval_95
    assert low <= 3.0 / fixed.parameters[held[0]] <= high
    assert fixed.parameters["K"] * fixed.parameters["G"] == pytest.approx(3.0, rel=0.02)
    assert fixed.parameters["tau"] == pytest.approx(0.3, rel=0.02)
    assert set(fixed.free) == {other, "tau"}


def test_a_positive_parameter_with_a_large_relative_std_keeps_a_positive_interval():
    """OLS gives ``sigma_b = sigma_e / ||u2||`` (orthogonal regressors): the fit's relative
    standard deviation agrees with it, and its interval ``b exp(+-1.96 sigma_z)`` stays
    positive although ``b - 1.96 sigma_b`` is negative."""
    data, u1, u2 = _regression_data(b=1.0, weak=0.02, noise=1.0)
    result = fit_least_squares(Regression(), data, free=("a", "b"),
                               initial={"b": 2.0})
    e = result.estimates["b"]
    residual = data.output("y") - result.simulate(data)[:, 0]
    ols_std = np.std(residual) / np.linalg.norm(u2)
    assert e.std == pytest.approx(ols_std, rel=0.15)
    assert e.logarithmic and e.relative_std == pytest.approx(e.std / e.value, rel=1e-9)
    assert e.value - Z95 * e.std < 0.0 < e.interval_95[0] < e.value < e.interval_95[1]
    assert e.interval_95 == pytest.approx((e.value * math.exp(-Z95 * e.relative_std),
                                           e.value * math.exp(Z95 * e.relative_std)))
    assert e.verdict in ("weakly identifiable", "not identifiable")
    assert result.estimates["a"].verdict == "identifiable"
    a = result.estimates["a"]  # linear parameter: symmetric interval
    assert a.interval_95 == pytest.approx((a.value - Z95 * a.std, a.value + Z95 * a.std))


def test_a_parameter_driven_to_its_bound_gets_no_symmetric_interval():
    data, _, _ = _regression_data(b=0.5, weak=1.0, noise=0.05)
    result = fit_least_squares(Regression(b_bounds=(1.0, 10.0)), data, free=("a", "b"),
                               initial={"b": 3.0})
    b, a = result.estimates["b"], result.estimates["a"]
    assert b.at_bound == "lower" and b.verdict == "at bound" and b.status == "at lower bound"
    assert b.value == pytest.approx(1.0)
    assert math.isnan(b.std) and not any(map(math.isfinite, b.interval_95))
    assert not any(map(math.isfinite, result.details["intervals_95"]["b"]))
    assert "lower bound" in b.reason
    # the other parameter is estimated with the bound active: finite, and around the truth
    assert a.at_bound is None and math.isfinite(a.std)
    assert a.interval_95[0] < 3.0 < a.interval_95[1]


def test_the_written_json_and_summary_hold_units_and_verdicts(tmp_path):
    data = _product_data()
    result = fit_least_squares(ProductLag(), data, free=("K", "G", "tau"),
                               fix_unidentifiable=True)
    paths = write_identification(result, tmp_path, data=data)
    rows = json.loads(paths["result"].read_text())["parameters"]
    assert rows["tau"]["unit"] == "s" and rows["tau"]["verdict"] == "identifiable"
    assert rows["tau"]["interval_95"][0] < rows["tau"]["value"] < rows["tau"]["interval_95"][1]
    held = [n for n in ("K", "G") if rows[n]["fixed"]]
    assert len(held) == 1 and rows[held[0]]["status"].startswith("fixed at prior")
    assert rows[held[0]]["verdict"] == "not identifiable" and rows[held[0]]["std"] is None
    text = paths["summary"].read_text()
    assert "| tau |" in text and "fixed at prior" in text and "N/bar" in text


def test_structures_state_the_units_of_their_parameters():
    from panto.identification.structures.oscillators import OscillatorStructure
    from panto.identification.structures.physical import PhysicalLinear

    physical = PhysicalLinear().units()
    assert physical["m_c"] == "kg" and physical["k_ph"] == "N/m" and physical["eta_delay"] == "s"
    oscillator = OscillatorStructure(3, friction=True)
    units = oscillator.units()
    assert set(units) == set(oscillator.parameter_names)
    assert units["m2"] == "kg" and units["c1"] == "N s/m" and units["p_gain"] == "N/bar"
