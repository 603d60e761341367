"""Which effect the diagnosis names, on synthetic pantograph data made by the linearised physical
model (``physical-linear``) plus ONE effect's augmentation, with sensor noise: the effect must be
named first and close most of the gap on a withheld run (another input realisation).

Cases that used to be misnamed on the virtual test bed: a lag of the bellow pressure (ranked
behind a lag of the motor height before the regressors went through the model's own input
path), a mass in the force-sensor path (named a compliant mode before parsimony decided between
candidates the withheld data cannot tell apart), and a hinge friction that sticks (entering as
an equivalent bellow pressure)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal as sps

from panto.identification.diagnosis.augmentations import AugmentedStructure, equivalent_input
from panto.identification.estimation.base import IdentificationData
from panto.identification.diagnosis.choice import choose
from panto.identification.diagnosis.pipeline import DiagnosisOptions, Trial, diagnose
from panto.identification.diagnosis.effects import PANTOGRAPH_ROLES
from panto.identification.structures.physical import PhysicalLinear

RATE = 50.0
DURATION = 20.0


def _inputs(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """APRBS-like motor height and bellow pressure (held levels, smoothed at 2 Hz)."""
    rng = np.random.default_rng(seed)
    n = int(DURATION * RATE)
    t = np.arange(n) / RATE

    def aprbs(mean: float, std: float, hold: tuple[float, float]) -> np.ndarray:
        out, i = np.empty(n), 0
        while i < n:
            k = int(rng.uniform(*hold) * RATE)
            out[i:i + k] = mean + std * rng.uniform(-1.7, 1.7)
            i += k
        b, a = sps.butter(2, 2.0 / (RATE / 2))
        return sps.filtfilt(b, a, out)

    return t, np.column_stack([aprbs(2.0, 0.03, (0.3, 1.5)), aprbs(4.0, 0.25, (0.5, 2.0))])


def _data(effect: str | None, setting: dict, values: dict, seed: int) -> IdentificationData:
    nominal = PhysicalLinear()
    t, u = _inputs(seed)
    blank = IdentificationData(t, u, np.zeros((len(t), 2)), ("eta", "p"), ("F_c", "y_cb"))
    structure = nominal if effect is None else AugmentedStructure(nominal, effect,
                                                                  PANTOGRAPH_ROLES, setting)
    y = np.asarray(structure.simulate({**structure.nominal(), **values}, blank), float)
    rng = np.random.default_rng(seed + 100)
    y = y + rng.normal(size=y.shape) * np.array([1.0, 1.5e-3])
    return IdentificationData(t, u, y, ("eta", "p"), ("F_c", "y_cb"))


def _closed(result) -> float:
    """Share of the gap (to the noise floor) the accepted effect removes, mean over outputs."""
    return float(np.mean(list(result.gap_closed().values())))


CASES = {
    "actuator_lag": ({"input": "p", "time_constant_s": 0.15}, {"actuator_lag:p": 0.15}),
    "sensor_inertia": ({"acceleration_scale": 1.0, "scale": 1.0},
                       {"sensor_inertia:F_c": 8.0}),
    "coulomb_friction": ({"presliding": 1.5e-3, "input_scale": 0.25},
                         {"coulomb_friction:p": -0.12, "coulomb_friction:presliding": 1.5e-3}),
}


@pytest.mark.parametrize("effect", sorted(CASES))
def test_the_hidden_effect_is_named_first_and_closes_the_gap(effect):
    setting, values = CASES[effect]
    train = _data(effect, setting, values, 1)
    validation = _data(effect, setting, values, 2)
    lines: list[str] = []
    # the nominal as one LM run (adequacy off): the effect's cost is stated against that nominal;
    # with the adequacy check (the default) a globally refitted nominal absorbs part of the 0.15 s
    # lag (validation F_c 96.1 % before the effect), and the lag, still named first, closes less
    result = diagnose(train, validation, structure="physical-linear",
                      options=DiagnosisOptions(max_effects=1, adequacy=False),
                      progress=lines.append)
    assert result.verdict == "effect" and result.effects[0] == effect, "\n".join(lines)
    step = result.steps[0]
    # the force fit on the withheld run rises and most of the residual energy goes
    assert step.fit_after["F_c"] > step.fit_before["F_c"] + 1.0, "\n".join(lines)
    assert step.energy_removed["F_c"] > 0.6, "\n".join(lines)
    # the diagnosis points to the discrimination design that exists for friction (issue 7)
    suggestion = result.next_experiment()
    if effect == "coulomb_friction":
        assert suggestion["design"] == "T_f" and "--discriminate T_f" in suggestion["command"]
        assert suggestion["status"] == "accepted"
    assert result.to_dict()["next_experiment"] == suggestion


def test_friction_acts_as_an_equivalent_bellow_pressure_on_both_outputs():
    """The hinge torque enters where the bellow torque does: the linearised model with
    ``p + c phi`` moves y_cb too (a force added to F_c alone would not)."""
    nominal = PhysicalLinear()
    assert equivalent_input(nominal, "coulomb_friction") == "p"
    assert equivalent_input(nominal, "cubic_stiffness") is None
    setting, values = CASES["coulomb_friction"]
    t, u = _inputs(3)
    blank = IdentificationData(t, u, np.zeros((len(t), 2)), ("eta", "p"), ("F_c", "y_cb"))
    structure = AugmentedStructure(nominal, "coulomb_friction", PANTOGRAPH_ROLES, setting)
    with_friction = structure.simulate({**structure.nominal(), **values}, blank)
    without = structure.simulate({**structure.nominal(), **values,
                                  "coulomb_friction:p": 0.0}, blank)
    np.testing.assert_allclose(without, nominal.simulate(nominal.nominal(), blank), atol=1e-9)
    change = np.std(with_friction - without, axis=0)
    assert change[0] > 1.0 and change[1] > 1e-4  # N on F_c, m on y_cb


def _trial(name: str, improvement: float, spread: float, delta_bic: float) -> Trial:
    return Trial(name, "", 0.1, name, {}, {}, 10.0, delta_bic, improvement, (), spread, {}, {},
                 True)


def test_parsimony_decides_between_candidates_the_withheld_data_cannot_tell_apart():
    folds = 4
    simple = _trial("sensor_inertia", 2.0, 0.4, -400.0)
    rich = _trial("extra_mode", 2.2, 0.8, -230.0)  # better by 0.2 < its standard error 0.4
    chosen = choose([(simple, None, None), (rich, None, None)], folds)[0]
    assert chosen.effect == "sensor_inertia"
    clear = _trial("extra_mode", 4.0, 0.8, -230.0)  # better beyond its standard error
    assert choose([(simple, None, None), (clear, None, None)], folds)[0].effect == "extra_mode"
    assert math.isclose(choose([(rich, None, None)], folds)[0].improvement, 2.2)


def test_input_side_effects_are_separate_candidates_per_input():
    """A lag on p and a lag on eta are different hypotheses: ranked (and refitted) apart, so the
    better-scoring one on one input cannot hide the other; output-side effects stay whole."""
    from panto.identification.diagnosis.ranking import _split_per_input

    x = np.zeros(4)
    regressors = {"actuator_lag": {"lag(eta, 0.08 s)": (x, {"input": "eta"}),
                                   "lag(p, 0.02 s)": (x, {"input": "p"}),
                                   "lag(p, 0.3 s)": (x, {"input": "p"})},
                  "offset": {"constant": (x, {})}}
    split = _split_per_input(regressors)
    assert set(split) == {"actuator_lag@eta", "actuator_lag@p", "offset"}
    assert set(split["actuator_lag@p"]) == {"lag(p, 0.02 s)", "lag(p, 0.3 s)"}


def test_candidates_the_runs_cannot_tell_apart_are_reported_beside_the_chosen_one():
    """A lag much shorter than the excitation's periods acts like a delay (held-out case 320 of
    the families: both +3.29 points on the withheld run, dBIC -3613 vs -3607): the delay is
    chosen (lower dBIC) and the lag reported as equally supported; a dBIC 10 or more apart is
    strong evidence (Kass & Raftery), and a gain outside the folds' standard error tells them
    apart on the withheld run."""
    from panto.identification.diagnosis.choice import alternatives

    folds = 4
    delay = _trial("input_delay", 3.29, 0.40, -3612.6)
    lag = _trial("actuator_lag", 3.29, 0.40, -3607.2)
    mode = _trial("extra_mode", 0.35, 0.14, -121.4)
    passing = [(t, None, None) for t in (delay, lag, mode)]
    chosen = choose(passing, folds)[0]
    assert chosen.effect == "input_delay"
    assert alternatives(chosen, passing, folds) == ("actuator_lag",)
    far = _trial("actuator_lag", 3.29, 0.40, -3600.0)  # 12.6 apart: strong evidence
    assert alternatives(delay, [(delay, None, None), (far, None, None)], folds) == ()
    weaker = _trial("actuator_lag", 2.9, 0.40, -3610.0)  # 0.39 below, tolerance 0.2
    assert alternatives(delay, [(delay, None, None), (weaker, None, None)], folds) == ()


def test_a_mass_above_load_cells_in_the_head_is_named_with_the_head_it_moves_with():
    """A measuring pantograph's force: load cells under the contact strips read the contact
    force less the strips' inertia, ``F_c - m_s xi''`` (EN 50317 corrects for it), with the head
    ``xi`` not recorded. Made here from the structure's own head motion and a five-point
    second difference (not the augmentation's code); the diagnosis must name the sensor mass
    moving with the head (simulating the head it was not given), as a positive mass, and take
    most of the force residual away (8 kg, as the bar's case above). The mass itself is not
    checked against the truth: the nominal refitted without the effect moved its head mass and
    dampers to imitate it (m3 6.7 -> 0.16 kg, two dampers at their bounds), and the refit from
    there shares the inertia with them (6.6 +- 0.3 kg when written; 2.8 +- 0.3 for 4 kg, whose
    0.8-point gain on these slow inputs is too small for the gap checks below)."""
    nominal, m_s = PhysicalLinear(outputs=("F_c", "y_cb", "xi")), 8.0

    def run(seed: int) -> IdentificationData:
        t, u = _inputs(seed)
        blank = IdentificationData(t, u, np.zeros((len(t), 3)), ("eta", "p"),
                                   ("F_c", "y_cb", "xi"))
        f_c, y_cb, xi = np.asarray(nominal.simulate(nominal.nominal(), blank), float).T
        padded = np.concatenate([[xi[0]] * 2, xi, [xi[-1]] * 2])
        accel = (-padded[4:] + 16 * padded[3:-1] - 30 * padded[2:-2] + 16 * padded[1:-3]
                 - padded[:-4]) * RATE ** 2 / 12.0
        y = np.column_stack([f_c - m_s * accel, y_cb])
        rng = np.random.default_rng(seed + 100)
        return IdentificationData(t, u, y + rng.normal(size=y.shape) * np.array([1.0, 1.5e-3]),
                                  ("eta", "p"), ("F_c", "y_cb"))

    lines: list[str] = []
    result = diagnose(run(1), run(2), structure="physical-linear",
                      options=DiagnosisOptions(max_effects=1, adequacy=False),
                      progress=lines.append)
    assert result.effects == ("sensor_inertia",), "\n".join(lines)
    step = result.steps[0]
    assert "moves with xi" in step.description, step.description
    assert step.parameters["sensor_inertia:F_c"] > 3 * step.std["sensor_inertia:F_c"]
    assert step.fit_after["F_c"] > step.fit_before["F_c"] + 1.0, "\n".join(lines)
    assert step.energy_removed["F_c"] > 0.6, "\n".join(lines)
