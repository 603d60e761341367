"""Correlations on request (issue 21): the correlation matrix of the estimates in the
identification report and ``panto identify --correlations``.

The structure ``y = a b u1 + delta b u2 + c u3 + d u4`` is built to have a known valley: the data
see ``a b`` through u1 and ``b`` alone only through the weak regressor ``delta u2``, so a and b
are strongly (negatively) correlated; c is seen apart from them; d is bounded at zero while the
truth is negative, so it ends at its bound and has no correlation. The independent check is the
correlation of the linear-regression covariance ``(G^T G)^-1`` of the sensitivities
``G = dy/d(a, b, c)`` at the estimate (white noise: the sandwich covariance reduces to it).
"""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from panto.cli import main
from panto.identification.estimation.base import IdentificationData, Identifier, ModelStructure
from panto.identification.estimation.correlations import correlation_matrix, parameter_correlations
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.estimation.reporting import write_identification

DELTA = 0.3  # weight of the regressor that separates b from a b
TRUTH = {"a": 2.0, "b": 1.5, "c": -0.7, "d": -0.5}


class ProductValley(ModelStructure):
    """``y = a b u1 + DELTA b u2 + c u3 + d u4`` with a, b positive and d >= 0."""

    name = "product-valley"
    input_names = ("u1", "u2", "u3", "u4")
    output_names = ("y",)
    parameter_names = ("a", "b", "c", "d")

    def nominal(self):
        return {"a": 1.0, "b": 1.0, "c": 0.0, "d": 1.0}

    def bounds(self):
        return {"a": (0.01, 100.0), "b": (0.01, 100.0), "c": (-10.0, 10.0), "d": (0.0, 10.0)}

    def units(self):
        return {"a": "N/m", "b": "m", "c": "N", "d": "N"}

    def simulate(self, parameters, data):
        p = self.nominal() | dict(parameters)
        u = [data.input(n) for n in self.input_names]
        return (p["a"] * p["b"] * u[0] + DELTA * p["b"] * u[1] + p["c"] * u[2]
                + p["d"] * u[3])[:, None]


def _data(seed: int = 3, n: int = 1500) -> IdentificationData:
    rng = np.random.default_rng(seed)
    inputs = rng.standard_normal((n, 4))
    data = IdentificationData(np.arange(n) * 0.01, inputs, np.zeros((n, 1)),
                              ProductValley.input_names, ("y",), {"y": "N"})
    y = ProductValley().simulate(TRUTH, data)[:, 0] + 0.05 * rng.standard_normal(n)
    return IdentificationData(data.time, inputs, y[:, None], data.input_names, ("y",),
                              {"y": "N"})


def _fit(data: IdentificationData, **options):
    return fit_least_squares(ProductValley(), data, free=("a", "b", "c", "d"), **options)


@pytest.fixture(scope="module")
def fitted():
    data = _data()
    return data, _fit(data)


def test_the_valley_pair_correlates_as_the_regression_covariance_says(fitted):
    data, result = fitted
    correlations = parameter_correlations(result)
    assert correlations["names"] == ["a", "b", "c"]
    assert correlations["left_out"] == {"d": "at its lower bound"}
    rho = np.array(correlations["matrix"])
    a, b = result.parameters["a"], result.parameters["b"]
    u1, u2, u3 = (data.input(n) for n in ("u1", "u2", "u3"))
    sensitivities = np.column_stack([b * u1, a * u1 + DELTA * u2, u3])
    expected = correlation_matrix(np.linalg.inv(sensitivities.T @ sensitivities))
    # analytically, for uncorrelated unit inputs: rho_ab = -a / sqrt(a^2 + DELTA^2)
    assert expected[0, 1] == pytest.approx(-a / np.hypot(a, DELTA), abs=0.01)
    assert rho[0, 1] < -0.95
    np.testing.assert_allclose(rho, expected, atol=0.02)
    assert abs(rho[0, 2]) < 0.1 and abs(rho[1, 2]) < 0.1
    np.testing.assert_allclose(rho, rho.T)
    np.testing.assert_allclose(np.diag(rho), 1.0)


def test_a_pure_product_has_unbounded_variances_and_is_left_out_named():
    """Without the separating regressor (delta = 0 in effect: u2 silent) a and b lie in a null
    direction: no finite correlation, both named."""
    data = _data()
    silent = IdentificationData(data.time, data.inputs * [1.0, 0.0, 1.0, 1.0], data.outputs,
                                data.input_names, data.output_names, data.units)
    correlations = parameter_correlations(_fit(silent))
    assert "a" not in correlations["names"] and "b" not in correlations["names"]
    assert "unbounded variance" in correlations["left_out"]["a"]
    assert "unbounded variance" in correlations["left_out"]["b"]
    assert "c" in correlations["names"]


def test_reports_show_the_matrix_only_on_request(fitted, tmp_path):
    data, result = fitted
    plain = write_identification(result, tmp_path / "plain", data=data)
    asked = write_identification(result, tmp_path / "asked", data=data, correlations=True)
    plain_json = json.loads(plain["result"].read_text())
    asked_json = json.loads(asked["result"].read_text())
    assert "correlations" not in plain_json
    assert asked_json.pop("correlations")["names"] == ["a", "b", "c"]
    assert asked_json == plain_json  # the flag adds the matrix and changes nothing else
    plain_md, asked_md = plain["summary"].read_text(), asked["summary"].read_text()
    assert "Correlation" not in plain_md
    assert asked_md.startswith(plain_md) and "## Correlations of the estimates" in asked_md
    assert "left out: d: at its lower bound" in asked_md
    rho_ab = parameter_correlations(result)["matrix"][0][1]
    assert f"| a | +1.00 | {rho_ab:+.2f} |" in asked_md
    plain_html, asked_html = plain["html"].read_text(), asked["html"].read_text()
    assert "Correlations of the estimates" not in plain_html
    assert "Correlations of the estimates" in asked_html and f"{rho_ab:+.2f}" in asked_html
    assert "d: at its lower bound" in asked_html


def test_panto_identify_correlations_prints_the_matrix(tmp_path, capsys, monkeypatch):
    from panto.identification.structures import registry

    data = _data(n=600)
    table = pd.DataFrame({"time": data.time, **{n: data.input(n) for n in data.input_names},
                          "y": data.output("y")})
    table.to_csv(tmp_path / "run.csv", index=False)

    def identify(run, *, executor=None, progress=None, **options):
        return fit_least_squares(ProductValley(), run, free=("a", "b", "c", "d"),
                                 fix_unidentifiable=options.get("fix_unidentifiable", False))

    monkeypatch.setattr(registry, "identifier",
                        lambda name: Identifier(name, "the product valley", identify))
    argv = ["identify", str(tmp_path / "run.csv"), "--model", "product-valley", "--inputs",
            "u1=u1", "u2=u2", "u3=u3", "u4=u4", "--outputs", "y=y", "--sample-rate", "100"]
    assert main([*argv, "--json", str(tmp_path / "plain.json")]) == 0
    plain = capsys.readouterr().out
    assert main([*argv, "--correlations", "--json", str(tmp_path / "asked.json")]) == 0
    asked = capsys.readouterr().out
    assert "correlations" not in plain
    assert "correlations of the estimates:" in asked and "left out: d: at its lower bound" in asked
    row = next(line.split() for line in asked.splitlines() if line.split()[:2] == ["a", "+1.00"])
    assert float(row[2]) < -0.9  # a against b: the valley
    plain_json = json.loads((tmp_path / "plain.json").read_text())
    asked_json = json.loads((tmp_path / "asked.json").read_text())
    assert "correlations" not in plain_json and asked_json["correlations"]["names"] == \
        ["a", "b", "c"]
