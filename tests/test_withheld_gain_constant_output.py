"""A validation run on which one output never changes (a force sensor reading zero while the head
never touches the wire): that output's fit is undefined, and the withheld gains are judged on the
others instead of turning NaN for every candidate (seen held-out three-mass/contact_loss/7013)."""
import math

import numpy as np
import pytest

from panto.identification.diagnosis.pipeline import _constant_outputs
from panto.identification.diagnosis.support import fit_text, withheld_gain
from panto.identification.estimation.base import IdentificationData, fit_percent


def _runs():
    rng = np.random.default_rng(3)
    t = np.arange(800) * 0.01
    y_cb = np.sin(2 * np.pi * 0.7 * t) + 0.05 * rng.standard_normal(len(t))
    measured = np.column_stack([np.zeros(len(t)), y_cb])  # F_c reads zero throughout
    validation = IdentificationData(t, np.sin(t)[:, None], measured, ("eta",), ("F_c", "y_cb"))
    current = np.column_stack([0.1 * np.sin(t), 0.7 * np.sin(2 * np.pi * 0.7 * t)])
    better = np.column_stack([0.1 * np.sin(t), 0.95 * np.sin(2 * np.pi * 0.7 * t)])
    return validation, current, better


def test_the_gain_is_judged_on_the_outputs_whose_fit_is_defined():
    validation, current, better = _runs()
    gain = withheld_gain(validation, current, better, 4)
    assert math.isnan(gain["fit_before"]["F_c"]) and math.isnan(gain["fit_after"]["F_c"])
    expected = fit_percent(validation.outputs[:, 1], better[:, 1]) - \
        fit_percent(validation.outputs[:, 1], current[:, 1])
    assert expected > 10.0
    assert gain["improvement"] == expected
    assert gain["best"] == expected
    assert _constant_outputs(validation) == ["F_c"]


@pytest.mark.filterwarnings("ignore:Mean of empty slice:RuntimeWarning")  # every fold undefined
def test_no_output_with_a_fit_leaves_the_gain_undefined():
    validation, current, better = _runs()
    flat = IdentificationData(validation.time, validation.inputs,
                              np.zeros_like(validation.outputs), ("eta",), ("F_c", "y_cb"))
    gain = withheld_gain(flat, current, better, 4)
    assert math.isnan(gain["improvement"]) and math.isnan(gain["best"])
    assert _constant_outputs(flat) == ["F_c", "y_cb"]


def test_an_undefined_fit_reads_undefined_in_the_reports():
    assert fit_text(97.64) == "97.6 %"
    assert fit_text(97.64, 2) == "97.64 %"
    assert fit_text(math.nan) == "undefined"
