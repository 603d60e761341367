"""Effect parameters with units (issue 21): the unit of each effect parameter derived from its name
and the data's units, recorded in ``report.json`` and shown in ``report.html`` and ``report.md``."""
from __future__ import annotations

import json

import numpy as np
import pytest

from panto.identification.diagnosis.pipeline import Diagnosis, Step
from panto.identification.diagnosis.report import write_report
from panto.identification.diagnosis.units import effect_parameter_unit, effect_parameter_units

RIG_UNITS = {"eta": "m", "p": "bar", "F_c": "N", "y_cb": "m"}

#: name -> unit as the effect vocabulary defines the parameter (issue 21's list).
EXPECTED = {
    "input_delay:eta": "s", "input_delay:p": "s", "actuator_lag:p": "s",
    "dead_zone:eta": "m", "saturation:F_c:low": "N", "saturation:F_c:high": "N",
    "saturation:p:low": "bar", "offset:F_c": "N", "offset:y_cb": "m",
    "sensor_inertia:F_c": "kg", "extra_mode:frequency": "Hz", "extra_mode:damping": "-",
    "coulomb_friction:F_c": "N", "coulomb_friction:p": "bar", "coulomb_friction:presliding": "m",
    "cubic_stiffness:F_c": "N/m^3", "F_f1": "N", "F_f2": "N", "F_f3": "N",
    "kc1": "1/m^2", "kc2": "1/m^2", "kc3": "1/m^2", "kq1": "1/m", "kq3": "1/m", "T_f": "N m",
    "k_c3": "N/m^3", "m_e": "kg", "f_e": "Hz", "zeta_e": "-",
}


@pytest.mark.parametrize("name, unit", EXPECTED.items(), ids=list(EXPECTED))
def test_unit_follows_from_the_name_and_the_data_units(name, unit):
    assert effect_parameter_unit(name, RIG_UNITS) == unit


def test_units_follow_the_data_not_a_fixed_table():
    """The same names on data in other units: the signal-level parameters take those units."""
    units = {"eta": "mm", "p": "kPa", "F_c": "kN", "y_cb": "mm"}
    derived = effect_parameter_units(["dead_zone:eta", "saturation:F_c:low", "offset:y_cb",
                                      "coulomb_friction:p", "input_delay:eta", "T_f"], units)
    assert derived == {"dead_zone:eta": "mm", "saturation:F_c:low": "kN", "offset:y_cb": "mm",
                       "coulomb_friction:p": "kPa", "input_delay:eta": "s", "T_f": "N m"}
    assert effect_parameter_unit("sensor_inertia:F_c", units) == "kN/(m/s^2)"


def test_extra_mode_gain_is_the_output_unit_per_drive_unit():
    assert effect_parameter_unit("extra_mode:gain", RIG_UNITS, output="F_c", drive="eta") == "N/m"
    assert effect_parameter_unit("extra_mode:gain", RIG_UNITS, output="y_cb",
                                 drive="p") == "m/bar"
    assert effect_parameter_unit("extra_mode:gain", RIG_UNITS) == "?"  # no target, no drive


def test_what_cannot_be_derived_is_marked_unknown():
    assert effect_parameter_unit("offset:F_c", {}) == "?"  # a signal without a unit
    assert effect_parameter_unit("x.cubic_stiffness", RIG_UNITS) == "?"  # a black-box term
    assert effect_parameter_unit("no_such_effect:F_c", RIG_UNITS) == "?"


def _diagnosis() -> Diagnosis:
    """A hand-made diagnosis of two accepted effects (an input delay, an extra mode driven by
    eta and ranked on F_c) on two outputs: only what the report reads."""
    n, outputs = 200, ("F_c", "y_cb")
    time = np.arange(n) * 0.01
    measured = np.column_stack([np.sin(time), np.cos(time)])
    bands = {o: {"edges_hz": [0.1, 1.0, 10.0], "before": [1.0, 2.0], "after": [0.5, 1.0]}
             for o in outputs}
    segments = {o: {"start_s": [0.0, 1.0], "rms_before": [1.0, 1.0], "rms_after": [0.5, 0.5]}
                for o in outputs}
    fits = {"F_c": 80.0, "y_cb": 90.0}
    steps = (Step("input_delay", "input_delay (input side; parameters input_delay:eta)",
                  {"input_delay:eta": 0.02}, {"input_delay:eta": 0.001}, fits, fits,
                  {o: 0.3 for o in outputs}, bands, segments),
             Step("extra_mode", "extra_mode (output side; parameters extra_mode:gain, ...)",
                  {"extra_mode:gain": 12.5, "extra_mode:frequency": 4.2,
                   "extra_mode:damping": 0.05}, {}, fits, fits, {o: 0.2 for o in outputs}, bands,
                  segments))
    ranking = {"F_c": {"candidates": [
        {"effect": "input_delay@eta", "variant": "eta(t-2)", "setting": {}, "err": 0.3,
         "significant": True},
        {"effect": "extra_mode", "variant": "mode(eta, 4.2 Hz, 0.05)", "err": 0.2,
         "significant": True, "setting": {"drive": "eta", "frequency_hz": 4.2, "damping": 0.05}}]}}
    judged = {"description": "", "delta_bic": -50.0, "significance": 9.0, "improvement": 3.0,
              "fold_spread": 0.1, "failed": []}
    tried = [{"effect": "input_delay", "variant": "eta(t-2)", "accepted": True, **judged},
             {"effect": "extra_mode", "variant": "mode(eta, 4.2 Hz, 0.05)", "accepted": True,
              **judged}]
    return Diagnosis("effect", ("input_delay", "extra_mode"), "physical-linear", outputs, fits,
                     fits, fits, {}, {}, {"significant": True, "reasons": ["a gap"]},
                     {"significant": False, "reasons": []}, {"text": "where"},
                     ({"ranking": ranking, "tried": tried},), steps, "summary", 1.0,
                     series={"time": time, "measured": measured, "before": measured,
                             "after": measured})


def test_report_records_and_shows_the_units(tmp_path):
    paths = write_report(_diagnosis(), tmp_path, units={"eta": "m", "F_c": "N", "y_cb": "m"})
    document = json.loads(paths["json"].read_text())
    assert document["steps"][0]["units"] == {"input_delay:eta": "s"}
    assert document["steps"][1]["units"] == {"extra_mode:gain": "N/m",
                                             "extra_mode:frequency": "Hz",
                                             "extra_mode:damping": "-"}
    markdown = paths["markdown"].read_text()
    assert "| input_delay:eta | 0.02 | 0.001 | s |" in markdown
    assert "| extra_mode:gain | 12.5 | – | N/m |" in markdown
    assert "| extra_mode:frequency | 4.2 | – | Hz |" in markdown
    html = paths["html"].read_text()
    assert "<th>parameter</th><th>value</th><th>± (1 σ)</th><th>unit</th>" in html
    assert "<td>input_delay:eta</td><td>0.02</td><td>0.001</td><td>s</td>" in html
    assert "<td>extra_mode:gain</td><td>12.5</td><td>–</td><td>N/m</td>" in html


def test_a_parameter_the_run_does_not_determine_says_so(tmp_path):
    """A refit's standard deviation that is not finite (a saturation's lower limit that no
    sample reaches ran to its bound, seen held-out 2155: -4581 N, deviation NaN) is written as
    not determined, in the markdown and the HTML, never as a number."""
    from panto.identification.diagnosis.report import NOT_DETERMINED

    diagnosis = _diagnosis()
    step = diagnosis.steps[1]
    step.std.update({"extra_mode:gain": float("nan"), "extra_mode:damping": float("inf")})
    paths = write_report(diagnosis, tmp_path, units={"eta": "m", "F_c": "N", "y_cb": "m"})
    markdown = paths["markdown"].read_text()
    assert f"| extra_mode:gain | 12.5 | {NOT_DETERMINED} | N/m |" in markdown
    assert f"| extra_mode:damping | 0.05 | {NOT_DETERMINED} | - |" in markdown
    assert "| input_delay:eta | 0.02 | 0.001 | s |" in markdown
    html = paths["html"].read_text()
    assert f"<td>extra_mode:gain</td><td>12.5</td><td>{NOT_DETERMINED}</td><td>N/m</td>" in html


def test_without_data_units_only_the_pantograph_models_lend_theirs(tmp_path):
    """A structure on the rig mapping computes in m, bar and N: those stand in for missing data
    units; another structure's signals stay unknown."""
    import dataclasses

    pantograph = write_report(_diagnosis(), tmp_path / "pantograph")
    other = write_report(dataclasses.replace(_diagnosis(), structure="linear-2"), tmp_path / "other")
    gain = [json.loads(p["json"].read_text())["steps"][1]["units"]["extra_mode:gain"]
            for p in (pantograph, other)]
    assert gain == ["N/m", "?"]
