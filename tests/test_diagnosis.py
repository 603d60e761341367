"""Sim-to-real gap diagnosis on synthetic systems with a known hidden effect (issue 8): the verdict
names the effect and the withheld fit improves; no effect gives ``none``; an effect outside the
library is not confidently misnamed."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal as sps

from panto.identification.diagnosis.augmentations import AugmentedStructure, mode_response
from panto.identification.estimation.base import IdentificationData, fit_percent
from panto.identification.diagnosis.pipeline import DiagnosisOptions, diagnose
from panto.identification.diagnosis.report import write_report
from panto.identification.diagnosis.support import effective_samples
from panto.identification.diagnosis.effects import SignalRoles
from panto.identification.structures.output_error import LinearOutputError, linear_output_error_from_data

DT = 0.005
MASS, STIFFNESS, DAMPING = 1.0, (2 * np.pi * 2.0) ** 2, 2 * 0.1 * 2 * np.pi * 2.0


def _force(n: int, seed: int) -> np.ndarray:
    b, a = sps.butter(2, 0.1)
    return 40.0 * sps.lfilter(b, a, np.random.default_rng(seed).normal(size=n))


def _oscillator(force: np.ndarray, extra=lambda x, v, t: 0.0, gain=lambda t: 1.0) -> np.ndarray:
    """``m x'' + c x' + k x + extra = gain(t) F(t - T)``, semi-implicit Euler (the test's own path)."""
    x = v = 0.0
    out = np.empty(len(force))
    previous = 0.0
    for t, f in enumerate(force.tolist()):
        out[t] = x
        v += DT / MASS * (gain(t) * previous - DAMPING * v - STIFFNESS * x - extra(x, v, t))
        x += DT * v
        previous = f
    return out


def _data(force: np.ndarray, x: np.ndarray, seed: int, noise: float = 0.01) -> IdentificationData:
    measured = x + noise * np.std(x) * np.random.default_rng(seed).normal(size=len(x))
    return IdentificationData(np.arange(len(x)) * DT, force[:, None], measured[:, None], ("F",),
                              ("x",), source="synthetic oscillator")


def _case(hidden=None, n=3000, **kw):
    f_train, f_valid = _force(n, 1), _force(n, 2)
    train = _data(f_train, _oscillator(f_train, **(hidden or {})), 3, **kw)
    validation = _data(f_valid, _oscillator(f_valid, **(hidden or {})), 4, **kw)
    return train, validation


def _run(train, validation, **options):
    lines = []
    result = diagnose(train, validation, structure="linear-2", progress=lines.append,
                      options=DiagnosisOptions(**options))
    return result, lines


def test_hidden_cubic_spring_is_named_and_closes_the_gap():
    train, validation = _case({"extra": lambda x, v, t: 3.0e3 * x ** 3})
    result, lines = _run(train, validation)
    assert result.verdict == "effect" and result.effects[0] == "cubic_stiffness", lines
    assert result.fit_before["x"] < 90.0  # the effect costs fit points
    assert result.gap_closed()["x"] > 0.9  # share of the residual energy removed
    assert result.fit_after["x"] > 97.0
    step = result.steps[0]
    assert step.parameters["x.cubic_stiffness"] < 0  # hardening: the term opposes the input
    assert any("diagnose: verdict" in line for line in lines)


def test_hidden_input_delay_is_named_with_its_delay_and_the_search_stops_there():
    """The delay is the only effect: once it is in the model the validation residual is within
    the noise, and no second round ranks and refits candidates on it (a second effect would be
    named on the noise's chance structure)."""
    delay = 6
    def delayed(force):
        return np.r_[np.zeros(delay), force[:-delay]]
    f_train, f_valid = _force(3000, 1), _force(3000, 2)
    train = _data(f_train, _oscillator(delayed(f_train)), 3)
    validation = _data(f_valid, _oscillator(delayed(f_valid)), 4)
    result, lines = _run(train, validation)
    assert result.verdict == "effect" and result.effects[0] == "input_delay", lines
    assert result.steps[0].parameters["input_delay:F"] == pytest.approx(delay * DT, abs=0.3 * DT)
    assert result.fit_after["x"] > result.fit_before["x"] + 5.0
    assert result.effects == ("input_delay",) and not result.remaining_gap["significant"], lines
    assert len(result.rounds) == 1 and DiagnosisOptions().max_effects > 1, lines
    assert any("leave is within the noise; stop" in line for line in lines), lines


def test_no_hidden_effect_gives_none():
    train, validation = _case()
    result, lines = _run(train, validation)
    assert result.verdict == "none", lines
    assert result.effects == ()
    assert not result.gap["significant"]
    # the adequacy's linear black box on the withheld run: as good as the exact nominal there
    level = result.adequacy["black_box_validation_fit"]
    assert set(level) == {"x"} and abs(level["x"] - result.fit_before["x"]) < 1.0, (
        level, result.fit_before)


def test_out_of_library_effect_is_not_confidently_misnamed():
    """A slowly drifting actuator gain (a time-varying system: no candidate is time-varying)."""
    drift = lambda t: 1.0 + 0.25 * math.sin(2 * np.pi * t * DT / 7.0)
    train, validation = _case({"gain": drift})
    result, lines = _run(train, validation)
    assert result.gap["significant"], lines  # the gap is seen ...
    assert result.verdict in ("unexplained", "effect"), lines
    if result.verdict == "effect":  # ... and an attribution may only close a small part of it
        assert min(result.gap_closed().values()) < 0.8, lines
        assert result.remaining_gap["significant"], lines


def test_report_json_and_html(tmp_path):
    train, validation = _case({"extra": lambda x, v, t: 3.0e3 * x ** 3}, n=2000)
    result, _ = _run(train, validation, max_effects=1)
    paths = write_report(result, tmp_path)
    data = json.loads(paths["json"].read_text())
    assert data["verdict"] == "effect" and data["effects"] == ["cubic_stiffness"]
    assert data["outputs"]["x"]["fit_after"] > data["outputs"]["x"]["fit_before"]
    html = paths["html"].read_text()
    assert "cubic_stiffness" in html and "data:image/png;base64," in html


def test_effective_sample_size_of_white_and_coloured_noise():
    rng = np.random.default_rng(0)
    white = rng.normal(size=20000)
    assert effective_samples(white) == pytest.approx(20000, rel=0.05)
    coloured = sps.lfilter([1.0], [1.0, -0.9], white)
    # AR(1): 1 + 2 sum rho^(2k) = (1 + rho^2) / (1 - rho^2) = 9.53
    assert effective_samples(coloured, 200) == pytest.approx(20000 / 9.53, rel=0.15)


def test_linear_oe_feedback_is_the_polynomial_oe_recursion():
    """Two paths: the structure's feedback simulation against a direct recursion."""
    rng = np.random.default_rng(1)
    u = rng.normal(size=500)
    structure = LinearOutputError(("u",), ("y",), 2).with_effect(
        "cubic_stiffness", {"output": "y", "drive": "u"}).with_effect(
        "offset", {"output": "y", "drive": "u"})
    values = {"y.f1": -1.5, "y.f2": 0.7, "y.u.b1": 0.3, "y.u.b2": 0.1,
              "y.cubic_stiffness": -0.5, "y.offset": 0.2}
    data = IdentificationData(np.arange(500) * 0.01, u[:, None], np.zeros((500, 1)), ("u",), ("y",))
    y = structure.simulate(values, data)[:, 0]
    ref = np.zeros(500)
    w = np.zeros(500)
    for t in range(500):
        ref[t] = (1.5 * ref[t - 1] if t >= 1 else 0) - (0.7 * ref[t - 2] if t >= 2 else 0) \
            + (0.3 * w[t - 1] if t >= 1 else 0) + (0.1 * w[t - 2] if t >= 2 else 0)
        w[t] = u[t] - 0.5 * ref[t] ** 3 + 0.2
    assert np.allclose(y, ref, atol=1e-12)


@pytest.mark.parametrize("order, friction", [(2, []), (4, [(0.3, 0.02), (-0.1, 0.0)]),
                                             (0, [(0.2, 0.0)]), (1, [(0.5, 1e-3)])])
def test_the_compiled_oe_recursion_is_the_loop_bit_for_bit(order, friction, monkeypatch):
    """The compiled recursion (output_error.RECURSION_SOURCE) against its Python loop: the same
    values to the last bit, with cubic and offset terms, tanh and sign friction, zero
    coefficients skipped, order 0; with the kernel switched off the loop runs."""
    from panto.identification.structures import output_error
    rng = np.random.default_rng(order)
    f = [1.0] + list(rng.uniform(-0.3, 0.3, order))
    if order >= 2:
        f[2] = 0.0  # a zero coefficient is skipped by both
    b = list(0.3 * rng.normal(size=order + 1))
    other, drive = (0.2 * rng.normal(size=800)).tolist(), rng.normal(size=800).tolist()
    arguments = (f, b, other, drive, -0.05, 0.1, friction)
    loop = output_error.recursion_loop(*arguments)
    assert output_error._recursion_kernel() is not None  # the suite's machines have gcc
    assert np.array_equal(output_error._recursion(*arguments), loop)
    assert np.all(np.isfinite(loop)) and np.std(loop) > 0.05
    called = []
    monkeypatch.setenv("PANTO_OE_KERNEL", "0")
    monkeypatch.setattr(output_error, "recursion_loop", lambda *a: called.append(1) or loop)
    output_error._recursion(*arguments)
    assert called


def test_arx_start_and_oe_recover_a_linear_system():
    force = _force(2000, 5)
    data = _data(force, _oscillator(force), 6, noise=0.0)
    structure = linear_output_error_from_data(data, 2)
    assert fit_percent(data.outputs[:, 0], structure.simulate({}, data)[:, 0]) > 99.9


def test_augmentations_transform_inputs_and_outputs_as_documented():
    data = IdentificationData(np.arange(200) * 0.01, np.linspace(-1, 1, 200)[:, None],
                              np.zeros((200, 1)), ("u",), ("y",))
    nominal = LinearOutputError(("u",), ("y",), 1, input_delay=0,
                                initial={"y.f1": 0.0, "y.u.b0": 1.0})  # y = u: identity
    roles = SignalRoles(position="y", force=None, actuators=("u",))
    u = data.inputs[:, 0]
    delay = AugmentedStructure(nominal, "input_delay", roles, {"delay_s": 0.025})
    assert np.allclose(delay.simulate({}, data)[10:, 0], np.interp(data.time[10:] - 0.025, data.time, u))
    zone = AugmentedStructure(nominal, "dead_zone", roles, {"width": 0.2, "centre": 0.0})
    assert np.allclose(zone.simulate({}, data)[:, 0], np.sign(u) * np.maximum(np.abs(u) - 0.2, 0))
    offset = AugmentedStructure(nominal, "offset", roles, {"coefficient": 0.3, "output": "y"})
    assert offset.mode == "wrapper"  # the identity model (n_k = 0) has no inside form
    assert np.allclose(offset.simulate({}, data)[:, 0], u + 0.3)
    step = np.r_[np.zeros(100), np.ones(4900)]
    response = mode_response(step, 5.0, 0.1, 0.001)
    assert abs(response[-1]) < 1e-3 and np.min(response) < -0.5  # zero static gain, rings


def test_fold_improvements_share_the_whole_run_change_and_ignore_a_quiet_blocks_scale():
    from panto.identification.diagnosis.support import fold_improvements

    n = 400
    t = np.arange(n) * 0.01
    y = np.sin(2 * np.pi * 0.5 * t)
    y[:100] = 0.01 * np.sin(2 * np.pi * 5 * t[:100])  # a quiet first block (a start transient)
    data = IdentificationData(t, np.zeros((n, 1)), y[:, None], ("u",), ("y",))
    current = y + 0.05 * np.cos(7 * t)
    simulated = current.copy()
    simulated[:100] = y[:100] + 0.01 * np.cos(7 * t[:100])  # better only in the quiet block
    folds = fold_improvements(data, current[:, None], simulated[:, None], 4)[:, 0]
    whole = fit_percent(y, simulated) - fit_percent(y, current)
    # Only block 0 changed: its value is K times the whole-run change, the others are zero,
    # so the folds' mean IS the whole-run improvement the acceptance compares it with.
    assert folds[1:] == pytest.approx(0.0, abs=1e-12)
    assert np.mean(folds) == pytest.approx(whole, rel=1e-12)
    # The block's own fit would have been normalised by its tiny variance: tens of points.
    own = fit_percent(y[:100], simulated[:100]) - fit_percent(y[:100], current[:100])
    assert own > 10 * abs(folds[0]) and abs(folds[0]) < 20.0


def test_training_only_lists_effects_the_withheld_run_cannot_judge():
    from panto.identification.diagnosis.pipeline import _training_only

    def trial(effect, bic, failed):
        return {"effect": effect, "variant": "v", "delta_bic": bic, "improvement": 0.01,
                "failed": tuple(failed)}

    no_gain = "validation improvement 0.01 not above the folds' standard error 0.2"
    rounds = [{"tried": [trial("actuator_lag", -4000.0, [no_gain]),
                         trial("input_delay", -3000.0, [no_gain, "no output's validation fit "
                                                        "improves by 0.2 points (best 0.05)"]),
                         trial("extra_mode", -5.0, ["dBIC -5 >= -10", no_gain]),
                         trial("offset", -80.0, ["F_c worse on validation by 1.00 points"]),
                         trial("coulomb_friction", -300.0, [])]}]
    found = _training_only(rounds, accepted=("coulomb_friction",))
    # decisive on training, rejected only for want of a validation gain: strongest first
    assert [f["effect"] for f in found] == ["actuator_lag", "input_delay"]
