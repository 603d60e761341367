"""The reports: templates, units, intervals that respect the sign, marks, no Python reprs.

The intervals are checked against ordinary least squares (an independent path) on a regression
with a weakly excited non-negative parameter; the demo's report is rendered from a small summary
written here (no demo run), and every page is searched for Python representations.
"""
from __future__ import annotations

import html
import math
import re

import numpy as np
import pandas as pd
import pytest

from panto import templating
from panto.identification.estimation.base import IdentificationData, ModelStructure
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.estimation.reporting import (
    html_report, parameter_records, sign_respecting_interval, write_identification)
from panto.identification.estimation.uncertainty import Z95

#: What a Python representation looks like in text: numpy reprs, quoted or long lists, dicts,
#: the bare singletons, NaN. (A bracketed pair of numbers is an interval and allowed.)
REPRS = re.compile(r"np\.\w+\(|array\(|\[\s*['\"]|\{\s*['\"]|\bTrue\b|\bFalse\b|\bNone\b"
                   r"|\bnan\b|\[\s*-?[\d.e+-]+\s*,\s*-?[\d.e+-]+\s*,")


def visible_text(page: str) -> str:
    """The text a reader sees: no stylesheet, no embedded images, no tags, entities decoded."""
    page = re.sub(r"<style>.*?</style>", " ", page, flags=re.S)
    page = re.sub(r"data:[\w/+]+;base64,[A-Za-z0-9+/=]+", " ", page)
    return html.unescape(re.sub(r"<[^>]+>", " ", page))


def assert_no_reprs(text: str) -> None:
    found = [text[max(0, m.start() - 60):m.end() + 30] for m in REPRS.finditer(text)]
    assert not found, found


def test_the_repr_check_finds_reprs():
    for bad in ("effects ['saturation']", "np.float64(3.2)", "fixed True", "std None",
                "{'a': 1}", "value nan", "[1.0, 2.0, 3.0]"):
        with pytest.raises(AssertionError):
            assert_no_reprs(bad)
    assert_no_reprs("interval [1.0, 2.0]; fit [%]; none; Nonlinear; 3 … 4")


class Regression(ModelStructure):
    """``y = a u1 + b u2 + c u3``: ``a`` free in sign, ``b >= 0`` (lower bound 0, optimised as
    is), ``c > 0`` (positive lower bound, optimised on its logarithm)."""

    name = "regression3"
    input_names = ("u1", "u2", "u3")
    output_names = ("y",)
    parameter_names = ("a", "b", "c")

    def nominal(self):
        return {"a": 1.0, "b": 1.0, "c": 1.0}

    def bounds(self):
        return {"a": (-100.0, 100.0), "b": (0.0, 100.0), "c": (1e-3, 1e3)}

    def units(self):
        return {"a": "N/m", "b": "kg", "c": "N.s/m"}

    def simulate(self, parameters, data):
        p = self.nominal() | dict(parameters)
        return (p["a"] * data.input("u1") + p["b"] * data.input("u2")
                + p["c"] * data.input("u3"))[:, None]


def _regression(seed: int = 3):
    rng = np.random.default_rng(seed)
    n = 1500
    u = np.column_stack([rng.standard_normal(n), 0.02 * rng.standard_normal(n),
                         rng.standard_normal(n)])
    y = u @ np.array([3.0, 0.5, 2.0]) + 0.3 * rng.standard_normal(n)
    data = IdentificationData(np.arange(n) * 0.01, u, y[:, None], ("u1", "u2", "u3"), ("y",),
                              {"y": "N"})
    return data, u, y


def test_a_non_negative_parameter_gets_an_interval_clipped_at_zero():
    data, u, y = _regression()
    result = fit_least_squares(Regression(), data, free=("a", "b", "c"))
    # independent path: ordinary least squares and its covariance s^2 (U^T U)^-1
    theta, *_ = np.linalg.lstsq(u, y, rcond=None)
    residual = y - u @ theta
    s2 = residual @ residual / (len(y) - 3)
    std = np.sqrt(np.diag(s2 * np.linalg.inv(u.T @ u)))
    records = {r["name"]: r for r in parameter_records(result)}
    b = records["b"]
    assert b["value"] == pytest.approx(theta[1], abs=0.05 * std[1])
    assert b["std"] == pytest.approx(std[1], rel=0.15)
    assert not b["logarithmic"] and b["lower_bound"] == 0.0
    low_normal = theta[1] - Z95 * std[1]
    assert low_normal < 0.0  # the weak regressor: the normal interval reaches below zero ...
    assert b["interval_shown"][0] == 0.0  # ... the one shown stops at the bound, with a note
    assert b["interval_shown"][1] == pytest.approx(theta[1] + Z95 * std[1], rel=0.15)
    assert "clipped" in b["interval_note"] and f"{b['interval_95'][0]:.3g}" in b["interval_note"]
    # a parameter free in sign keeps its symmetric interval; a positive one is log-normal
    a, c = records["a"], records["c"]
    assert a["interval_shown"] == pytest.approx(list(a["interval_95"]))
    assert a["interval_note"] == ""
    assert c["logarithmic"] and 0.0 < c["interval_shown"][0] < 2.0 < c["interval_shown"][1]
    assert c["interval_shown"][0] * c["interval_shown"][1] == pytest.approx(c["value"] ** 2)


def test_sign_respecting_interval_cases():
    # lower bound 0: clipped; no bound known: kept, said that the sign is open
    assert sign_respecting_interval(1.0, (-0.96, 2.96), lower_bound=0.0)[:2] == (0.0, 2.96)
    low, high, note = sign_respecting_interval(1.0, (-0.96, 2.96))
    assert (low, high) == (-0.96, 2.96) and "sign" in note
    assert sign_respecting_interval(1.0, (None, None))[2] == ""
    assert all(math.isnan(v) for v in sign_respecting_interval(1.0, (None, None))[:2])


def test_identification_report_has_units_marks_and_no_reprs(tmp_path):
    data, _, _ = _regression()
    # c held at a bound that excludes its truth (2.0): marked, no interval
    result = fit_least_squares(Regression(), data, free=("a", "b", "c"),
                               bounds={"c": (0.1, 1.0)})
    paths = write_identification(result, tmp_path, data=data)
    page = paths["html"].read_text()
    text = visible_text(page)
    assert_no_reprs(text)
    assert_no_reprs(paths["summary"].read_text())
    assert "N.s/m" in text and "kg" in text and "N/m" in text
    assert "at upper bound" in text
    assert "data:image/png;base64," in page
    # without the bound on c, b is estimated: its interval shown stops at 0, with the note
    free = fit_least_squares(Regression(), data, free=("a", "b", "c"))
    text = visible_text(html_report(free, {}))
    assert_no_reprs(text)
    assert "clipped at its lower bound 0" in text and "0 … " in text
    # the fit series behind the overview: measured and simulated, in the data's units
    series = pd.read_csv(paths["series_training"])
    assert list(series.columns) == ["time [s]", "y_measured [N]", "y_simulated [N]"]
    fit = 100 * (1 - np.linalg.norm(series["y_measured [N]"] - series["y_simulated [N]"])
                 / np.linalg.norm(series["y_measured [N]"] - series["y_measured [N]"].mean()))
    assert fit == pytest.approx(result.fit["y"], abs=1e-6)


def test_templates_escape_what_they_are_given():
    page = templating.render("sections.html.j2", title="<b>x</b>", written="", head=[
        templating.paragraph("a <script>alert(1)</script> & b")], sections=[])
    assert "<script>" not in page and "&lt;script&gt;" in page and "&lt;b&gt;x" in page


def _summary() -> dict:
    estimate = {"name": "m4", "value": 18.8, "unit": "kg", "std": 2.8, "relative_std": 0.15,
                "interval_95": [14.1, 25.1], "logarithmic": True, "verdict": "weakly identifiable",
                "at_bound": None, "fixed": False, "status": "estimated", "group": ["m4", "k_p"],
                "reason": "relative standard deviation 0.15 > 0.1"}
    damping = {"name": "c2", "value": 30.0, "unit": "N.s/m", "std": 20.0, "relative_std": 0.67,
               "interval_95": [-9.2, 69.2], "logarithmic": False, "lower_bound": 0.0,
               "verdict": "not identifiable", "at_bound": None, "fixed": False,
               "status": "estimated", "group": [], "reason": "relative standard deviation 0.67"}
    at_bound = {"name": "k", "value": 1e5, "unit": "N/m", "std": None, "relative_std": None,
                "interval_95": [None, None], "logarithmic": True, "verdict": "at bound",
                "at_bound": "upper", "fixed": False, "status": "at upper bound", "group": [],
                "reason": "at its upper bound"}
    statistics = [  # the reference pantograph inside, the identified one outside: no failure
        {"statistic": "mean", "label": "mean contact force Fm (N)", "value": 131.0,
         "reference_pantograph": 115.0, "target": [110, 120], "inside": False},
        {"statistic": "std", "label": "standard deviation σ (N)", "value": 24.0,
         "reference_pantograph": 45.0, "target": [32, 40], "inside": False}]
    return {
        "quick": True, "wall_time_s": 12.0, "failed_steps": [],
        "steps": [{"name": "identification", "title": "identify", "status": "ok", "seconds": 1.0,
                   "message": ""},
                  {"name": "cosim", "title": "co-simulate", "status": "ok", "seconds": 1.0,
                   "message": ""}],
        "identification": {
            "comparison": {"ranking_validation": ["physical-linear"]},
            "comparison_markdown": "| structure | fit [%] |\n|---|---|\n| physical-linear | 80 |",
            "physical": {"parameters": {"m4": 18.8}, "std": {"m4": 2.8},
                         "fit_training": {"F_c": np.float64(80.0)}, "fit_validation": {"F_c": 75.0},
                         "nominal_fit_validation": {"F_c": 60.0},
                         "parameter_file": "identification/parameters.json",
                         "estimates": [estimate, damping, at_bound],
                         "fixed_at_prior": {"m1": "not identifiable"},
                         "verdict_rule": "a rule"},
            "plots": {"fit": "identification/fit.png", "comparison": "comparison/comparison.png"},
            "sensitivity": {"natural_frequencies_hz": [3.9, 10.2], "ranking": ["c1", "k"],
                            "plot": "identification/eigenvalues.png"}},
        "cosim": {"speed_kmh": 300.0, "line": "en50318-2002", "parameters_from": "identified",
                  "pressure_bar": 4.5, "static_force_N": 120.0, "statistics": statistics,
                  "inside": 0, "reference_inside": 2, "message": "7200 steps; no contact loss",
                  "plots": []}}


def test_demo_report_shows_units_intervals_and_the_en50318_check_without_reprs(tmp_path):
    from panto.report import write_report

    page = write_report(_summary(), tmp_path).read_text()
    text = visible_text(page)
    assert_no_reprs(text)
    assert "14.1 … 25.1" in text  # log-normal, as estimated
    assert "0 … 69.2" in text and "clipped at its lower bound 0" in text  # never negative
    assert "at upper bound" in text and "kg" in text and "N.s/m" in text
    # the reference pantograph's statistics pass or fail; the identified one's only sit
    table = re.search(r"EN 50318:2002 range.*?</table>", page, flags=re.S).group(0)
    rows = [visible_text(r) for r in re.findall(r"<tr>.*?</tr>", table, flags=re.S)]
    assert "pass" in rows[0] and "above the range" in rows[0]
    assert "fail" in rows[1] and "below the range" in rows[1]
    assert "outside" not in text.lower()
    assert "line model" in text and "not acceptance limits" in text
    # the summary's line check counts what the table shows
    assert "1 of 2 statistics inside the ranges: the line model does not pass" in text
    assert "Missing" not in text and "cannot show" not in text


def test_diagnosis_report_has_no_reprs_and_saves_its_series(tmp_path):
    from test_diagnosis import _case, _run

    from panto.identification.diagnosis.report import write_report

    train, validation = _case({"extra": lambda x, v, t: 3.0e3 * x ** 3}, n=2000)
    result, _ = _run(train, validation, max_effects=1)
    paths = write_report(result, tmp_path)
    page = paths["html"].read_text()
    assert_no_reprs(visible_text(page))
    assert "<style>" in page and "Written by panto" in page  # the shared base template
    series = pd.read_csv(paths["series"])
    measured, before, after = (series[f"x_{k}"].to_numpy() for k in ("measured", "before",
                                                                      "after"))

    def fit(simulated):
        return 100 * (1 - np.linalg.norm(measured - simulated)
                      / np.linalg.norm(measured - measured.mean()))

    # the saved series are the ones the verdict was computed on
    assert fit(before) == pytest.approx(result.fit_before["x"], abs=0.05)
    assert fit(after) == pytest.approx(result.fit_after["x"], abs=0.05)
