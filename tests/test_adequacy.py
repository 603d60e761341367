"""Adequacy before anything else (issue 19): the nominal beside a black box of its order.

The plant is this test suite's own three-mass model (``test_global_fit``: solve_ivp on Newton's
equations per mass, not the structure's code). A fit stuck from the defaults is told apart from
one at the optimum, a structure missing a mode is told apart from a fit that did not converge, and
the diagnosis refits a stuck nominal globally instead of naming an effect for its misfit.
"""
import math

import numpy as np
import pytest

from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.diagnosis.refit import linear_explains
from panto.identification.estimation.base import IdentificationData, fit_percent
from panto.identification.estimation.global_fit import GlobalFitOptions, fit_global
from panto.identification.estimation.least_squares import fit_least_squares
from panto.identification.structures.adequacy import check_adequacy, state_order
from panto.identification.structures.oscillators import OscillatorStructure, identify_oscillator
from test_global_fit import F_0, TRUTH, Y_0, _inputs, _three_mass

QUICK = GlobalFitOptions(data_starts=1, perturbations=1)


def _run(seed: int, duration: float = 12.0) -> IdentificationData:
    rng = np.random.default_rng(seed)
    t, eta, p = _inputs(duration, rng)
    force = _three_mass(t, eta, p)
    measured = force + 0.03 * force.std() * rng.normal(size=len(t))
    return IdentificationData(t, np.column_stack([eta, p]), measured[:, None], ("eta", "p"),
                              ("F_c",), {"eta": "m", "p": "bar", "F_c": "N"})


@pytest.fixture(scope="module")
def train() -> IdentificationData:
    return _run(1)


def test_a_stuck_start_is_not_converged_and_the_global_fit_is_adequate(train):
    structure = OscillatorStructure(3, outputs=("F_c",))
    assert state_order(structure, structure.nominal(), train) == 6
    floor = fit_percent(train.outputs[:, 0], structure.simulate(
        {**TRUTH, "F_0": F_0, "y_0": Y_0}, train)[:, 0])
    stuck = fit_least_squares(structure, train, free=structure.default_free(),
                              max_evaluations=400)  # one run from the defaults, the diagnosis' budget
    assert stuck.fit["F_c"] < floor - 3.0  # it stops far from the noise floor
    first = check_adequacy(structure, stuck, train)
    assert first.verdict == "not converged" and first.clearly_better
    assert first.black_box_fit["F_c"] > floor - 0.3  # the black box reaches the floor itself
    assert first.p_value < 0.01 and "no nonlinear effect" in first.message
    best = identify_oscillator(train, masses=3, friction=False, outputs=("F_c",),
                               global_fit=QUICK, adequacy=True)  # `panto identify --initial data`
    assert best.details["adequacy"]["verdict"] == "adequate", best.message
    assert "adequacy: nominal vs black box" in best.message
    second = check_adequacy(structure, best, train, reference=first)
    assert second.black_box is first.black_box  # reused, not refitted
    assert second.verdict == "adequate", second.message
    assert abs(second.gap["F_c"]) < 0.2
    assert second.to_dict()["verdict"] == "adequate"


def test_a_structure_missing_a_mode_cannot_express_the_data(train):
    structure = OscillatorStructure(2, outputs=("F_c",))
    fitted = fit_global(structure, train, free=structure.default_free(), options=QUICK)
    adequacy = check_adequacy(structure, fitted, train)
    assert adequacy.orders == (4, 6)
    assert adequacy.verdict == "cannot express", adequacy.message
    assert adequacy.gap["F_c"] > 0.2


def test_a_nonlinear_effect_must_beat_the_black_box_on_the_withheld_run():
    """The black box has more parameters than the refitted structure: it is compared on the
    validation run (withheld), where a training advantage of either counts for nothing."""
    trial = {"fit_validation": {"F_c": 90.1}, "fit_train": {"F_c": 99.0}, "failed": (),
             "accepted": True}
    level = {"F_c": 90.0}
    verdict = linear_explains("coulomb_friction", trial, level)
    assert verdict["accepted"] is False and "linear black box" in verdict["failed"][0]
    assert linear_explains("actuator_lag", trial, level) == {}  # a linear effect may close it
    assert linear_explains("coulomb_friction", {**trial, "fit_validation": {"F_c": 91.0},
                                                 "fit_train": {"F_c": 80.0}}, level) == {}
    assert linear_explains("coulomb_friction", trial, None) == {}


def test_the_diagnosis_refits_a_stuck_nominal_instead_of_naming_its_misfit(train):
    lines: list[str] = []
    result = diagnose(train, _run(5), structure="three-mass", progress=lines.append,
                      options=DiagnosisOptions(max_refits=2, adequacy=True,
                                               global_fit=None))
    text = "\n".join(lines)
    assert "refitting the nominal globally" in text, text
    assert result.adequacy is not None and result.adequacy["verdict"] == "adequate", text
    assert result.verdict == "none", text
    assert math.isfinite(result.fit_train["F_c"])


def test_a_constant_input_is_left_out_of_the_black_box(train):
    import dataclasses

    from panto.identification.estimation.base import IdentificationError
    from panto.identification.structures.adequacy import _varying_inputs

    held = dataclasses.replace(train, inputs=np.column_stack([train.inputs[:, 0],
                                                              np.full(len(train), 4.5)]))
    varying = _varying_inputs(held)  # one-input runs record p held at 4.5 bar
    assert varying.input_names == ("eta",) and varying.inputs.shape == (len(train), 1)
    assert _varying_inputs(train) is train
    with pytest.raises(IdentificationError, match="every input is constant"):
        _varying_inputs(dataclasses.replace(train, inputs=np.ones_like(train.inputs)))
