"""The independent benchmark families' plants (``benchmarks/effect_plants.py``) obey their physics,
each checked by a path apart from the plant's Runge-Kutta loop: the clean plant against the exact
linear response (``scipy.signal.lsim`` of a state space written here from the chain matrices),
static equilibrium by the whole chain's force balance, the friction force within its Coulomb
bound, a pure delay as an exact shift, a unilateral contact that never pulls, the sensor mass's
inertia against the second difference of the head's height; and the harness's split and guard.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from fixtures.excitations import load_benchmark


@pytest.fixture(scope="module")
def ep():
    return load_benchmark("effect_plants")


@pytest.fixture(scope="module")
def harness():
    return load_benchmark("diagnosis_families")


def _truth(ep, masses: int, seed: int = 5) -> dict:
    return ep.plants.draw_oscillator_truth(masses, np.random.default_rng(seed))


def _run(ep, excitation: str = "aprbs", seconds: float = 2.0, rate: float = 200.0, seed: int = 2):
    rng = np.random.default_rng(seed)
    time = np.arange(int(seconds * rate)) / rate
    eta, p = ep.excitation(excitation, rng, time, rate, 2)
    return time, eta, p


def _state_space(truth: dict, masses: int):
    """``x' = A x + B [eta, p, 1]`` for the state ``[x_1..x_n, v_1..v_n]`` from M, K, C."""
    m = np.diag([truth[f"m{i + 1}"] for i in range(masses)])
    k = np.zeros((masses, masses))
    c = np.zeros((masses, masses))
    for i in range(masses):
        for matrix, kind in ((k, "k"), (c, "c")):
            value = truth[f"{kind}{i + 1}"]
            matrix[i, i] += value
            if i > 0:
                matrix[i - 1, i - 1] += value
                matrix[i, i - 1] -= value
                matrix[i - 1, i] -= value
    k[-1, -1] += truth["k_E"]
    forcing = np.zeros((masses, 3))
    forcing[-1, 0] = truth["k_E"]
    forcing[0, 1] = truth["p_gain"]
    forcing[0, 2] = truth["F_0"] + truth["k1"] * truth["y_0"]
    inverse = np.linalg.inv(m)
    a = np.block([[np.zeros((masses, masses)), np.eye(masses)], [-inverse @ k, -inverse @ c]])
    b = np.vstack([np.zeros((masses, 3)), inverse @ forcing])
    return a, b


@pytest.mark.parametrize("masses", [2, 3], ids=["two-mass", "three-mass"])
def test_clean_plant_agrees_with_the_exact_linear_response(ep, masses):
    truth = _truth(ep, masses)
    time, eta, p = _run(ep, "multisine")
    run = ep.EffectPlant(truth).simulate(time, eta, p)
    a, b = _state_space(truth, masses)
    u = np.column_stack([eta, p, np.ones_like(eta)])
    x0 = -np.linalg.solve(a, b @ u[0])
    c = np.eye(2 * masses)
    _, _, states = signal.lsim((a, b, c, np.zeros((2 * masses, 3))), u, time, X0=x0, interp=True)
    head = states[:, masses - 1]
    expected = {"xi": head, "y_cb": states[:, masses - 2], "F_c": truth["k_E"] * (head - eta)}
    measured = ep.EffectPlant(truth).measure(run, time, 0, ("F_c", "y_cb", "xi"))
    measured["y_cb"] = measured["y_cb"] - truth["y_cb_offset"]
    for name, reference in expected.items():
        assert np.ptp(reference) > 0
        error = np.max(np.abs(measured[name] - reference)) / np.ptp(reference)
        assert error < 1e-6, (name, error)


@pytest.mark.parametrize("effect, setting", [("clean", {}), ("cubic_stiffness", {"k3": 2e5})])
def test_constant_inputs_rest_in_the_chains_force_balance(ep, effect, setting):
    """At rest the contact force carries the bellow force less the base spring's, whatever the
    inner springs: ``F_c = p_gain p + F_0 - k_1 d - k_3 d^3`` with ``d = x_1 - y_0``."""
    truth = _truth(ep, 3, seed=9)
    time = np.arange(300) / 100.0
    eta, p = np.full_like(time, 2.012), np.full_like(time, 4.8)
    run = ep.EffectPlant(truth, effect, setting).simulate(time, eta, p)
    d = run["x1"][0] - truth["y_0"]
    balance = truth["p_gain"] * 4.8 + truth["F_0"] - truth["k1"] * d - setting.get("k3", 0.0) * d ** 3
    assert np.ptp(run["F_c"]) < 1e-8 * abs(balance)
    assert run["F_c"][-1] == pytest.approx(balance, rel=1e-9)
    assert d > 0.01  # the bellow lifts mass 1 well above the relaxed height (k3 d^3 counts)


def test_friction_force_is_bounded_by_its_coulomb_level(ep):
    truth = _truth(ep, 2)
    time, eta, p = _run(ep, "aprbs")
    run = ep.EffectPlant(truth, "coulomb_friction", {"F_f": 12.0}).simulate(time, eta, p)
    assert np.max(np.abs(run["friction"])) <= 12.0
    assert np.max(np.abs(run["friction"])) > 0.95 * 12.0  # it slides: the bound is reached
    assert np.all(run["friction"] * run["state"][2] <= 0.0)  # it opposes mass 1's velocity


@pytest.mark.parametrize("target, column", [("eta", "F_c"), ("p", "y_cb")])
def test_input_delay_shifts_the_outputs_by_exactly_the_delay(ep, target, column):
    truth = _truth(ep, 2)
    time, eta, p = _run(ep, "multisine", rate=100.0)
    if target == "eta":  # the other input held: the whole response is that of the delayed one
        p = np.full_like(p, p[0])
    else:
        eta = np.full_like(eta, eta[0])
    shift = 7
    delayed = ep.EffectPlant(truth, "input_delay", {"tau": shift / 100.0, "target": target})
    clean = ep.EffectPlant(truth).measure(ep.EffectPlant(truth).simulate(time, eta, p), time, 0,
                                          (column,))[column]
    late = delayed.measure(delayed.simulate(time, eta, p), time, 0, (column,))[column]
    scale = np.ptp(clean)
    assert np.max(np.abs(late[shift:] - clean[:-shift])) < 1e-9 * scale
    assert np.max(np.abs(late[:shift] - clean[0])) < 1e-9 * scale  # at rest until the delay
    assert np.max(np.abs(late - clean)) > 1e-3 * scale  # and not the undelayed response


def test_unilateral_contact_never_pulls_and_the_head_lifts_off(ep):
    truth = _truth(ep, 2)
    truth["F_0"] -= 0.7 * (truth["p_gain"] * 4.5 + truth["F_0"])  # 30 % of the preload
    time, eta, _ = _run(ep, "aprbs")
    p = np.full_like(time, 4.5)
    lossy = ep.EffectPlant(truth, "contact_loss", {"preload_scale": 0.3}).simulate(time, eta, p)
    bilateral = ep.EffectPlant(truth).simulate(time, eta, p)
    assert np.min(lossy["F_c"]) >= 0.0
    lifted = lossy["F_c"] == 0.0
    assert 0.01 < np.mean(lifted) < 0.9
    assert np.min(bilateral["F_c"]) < -10.0  # the same plant with a bilateral contact pulls


def test_sensor_mass_adds_its_inertia_to_the_measured_force(ep):
    truth = _truth(ep, 3)
    time, eta, p = _run(ep, "multisine", rate=500.0, seconds=2.0)
    plant = ep.EffectPlant(truth, "sensor_inertia", {"m_s": 0.8})
    run = plant.simulate(time, eta, p)
    excess = plant.measure(run, time, 0, ("F_c",))["F_c"] - run["F_c"]
    head = run["x3"]
    second_difference = (head[2:] - 2 * head[1:-1] + head[:-2]) * 500.0 ** 2
    inertia = 0.8 * second_difference
    assert np.max(np.abs(excess[1:-1] - inertia)) < 0.02 * np.ptp(inertia)


def test_offset_differs_between_training_and_validation(ep):
    truth = _truth(ep, 2)
    time, eta, p = _run(ep, "ramps", seconds=1.0)
    plant = ep.EffectPlant(truth, "offset", {"d": 6.0, "sign": -1.0})
    run = plant.simulate(time, eta, p)
    train, validation = (plant.measure(run, time, i, ("F_c",))["F_c"] for i in (0, 1))
    np.testing.assert_allclose(train - validation, -6.0, atol=1e-9)
    np.testing.assert_allclose(train - run["F_c"], -3.0, atol=1e-9)


def test_a_clean_case_costs_nothing_and_a_delay_costs_fit(ep):
    spec = ep.draw_spec("two-mass", "clean", 3, quick=True)
    clean = ep.effect_case(replace(spec, duration=2.0, rate=50.0))
    assert all(value == 0.0 for value in clean.detectability.values())
    delay = ep.effect_case(replace(spec, label="input_delay", duration=2.0, rate=50.0,
                                   strength=1.0, snr_db=40.0))
    assert delay.strongest > 2.0
    train, validation = delay.runs
    assert not np.allclose(train["eta"], validation["eta"])  # two input realisations
    # a linear plant's free run does not depend on the integration step (RK4 at half the step)
    assert clean.reproducible and delay.reproducible
    assert max(abs(v) for v in delay.step_drift.values()) < 0.01


def test_an_unscored_case_has_the_same_runs_and_ceiling_without_the_scores(ep):
    """``scored=False`` (the tests that diagnose one case) leaves out the runs behind the
    detectability and the step drift only: the recorded runs, the plant and the ceiling are the
    scored case's, bit for bit."""
    spec = replace(ep.draw_spec("two-mass", "actuator_lag", 5, quick=True), duration=2.0,
                   rate=50.0)
    scored, unscored = ep.effect_case(spec), ep.effect_case(spec, scored=False)
    assert scored.detectability and not unscored.detectability and not unscored.step_drift
    assert unscored.ceiling == scored.ceiling and unscored.plant.setting == scored.plant.setting
    assert unscored.plant.truth == scored.plant.truth
    for mine, theirs in zip(unscored.runs, scored.runs):
        for key in ("time", "eta", "p", "noise_std"):
            assert np.array_equal(mine[key], theirs[key]), key
        for name in spec.outputs:
            for key in ("outputs", "clean"):
                assert np.array_equal(mine[key][name], theirs[key][name]), (key, name)
    with pytest.raises(ValueError, match="unscored"):
        unscored.strongest
    with pytest.raises(ValueError, match="unscored"):
        unscored.reproducible


def test_a_head_bouncing_on_the_wire_is_not_reproducible_at_half_the_step(ep):
    """Tuning case three-mass/contact_loss/23: a head that flies a quarter of the time. Each
    impact's timing shifts the next, so the same plant integrated at half the step loses many
    fit points against its own record (the ceiling only the identical integration reaches).
    Shorter runs of the same plant (4-10 s) stay reproducible: the divergence takes time."""
    spec = ep.draw_spec("three-mass", "contact_loss", 23, quick=True)
    case = ep.effect_case(spec)
    assert np.mean(case.runs[1]["clean"]["F_c"] <= 0.0) > 0.1  # it flies
    assert not case.reproducible and case.step_drift["F_c"] > 5.0, case.step_drift


def test_split_is_stable_and_the_held_out_split_is_guarded(harness):
    splits = [harness.split_of("two-mass", seed) for seed in range(400)]
    assert splits == [harness.split_of("two-mass", seed) for seed in range(400)]
    assert 0.15 < splits.count("heldout") / 400 < 0.35
    sequence = harness.case_sequence("tune")
    assert all(harness.split_of(s.family, s.seed) == "tune" for s in (next(sequence)
                                                                     for _ in range(20)))
    with pytest.raises(SystemExit):
        harness.parse_arguments(["--split", "heldout"])
    assert harness.parse_arguments(["--split", "heldout", "--i-am-not-tuning"]).split == "heldout"
    with pytest.raises(SystemExit):
        harness.parse_arguments(["--options", "no_such_option=1"])
    options = harness.diagnosis_options(harness.parse_arguments(
        ["--options", "adequacy=true", "max_effects=2"]).raw_options)
    assert options.adequacy is True and options.max_effects == 2


def test_scores_follow_the_labels(harness):
    base = {"strongest": 5.0, "gap_closed": {"F_c": 0.9}, "detectability": {"F_c": 5.0}}
    assert harness.score({**base, "label": "hysteresis", "verdict": "unexplained",
                          "effects": []})["correct"]
    assert not harness.score({**base, "label": "hysteresis", "verdict": "effect",
                              "effects": ["cubic_stiffness"]})["correct"]
    assert not harness.score({**base, "label": "clean", "verdict": "effect",
                              "effects": ["extra_mode"]})["correct"]
    right = harness.score({**base, "label": "dead_zone", "verdict": "effect",
                           "effects": ["dead_zone", "offset"]})
    assert right["correct"] and right["gap_closed_main"] == 0.9 and right["strong"]


def test_a_tie_the_diagnosis_states_counts_only_in_its_own_score(harness):
    """"The runs cannot tell input_delay from actuator_lag" for a lag: wrong on top-1, right on
    the side score; an alternative of a later name or of an unexplained verdict counts in
    neither."""
    base = {"strongest": 5.0, "gap_closed": {"F_c": 0.9}, "detectability": {"F_c": 5.0},
            "label": "actuator_lag", "verdict": "effect"}
    tied = harness.score({**base, "effects": ["input_delay"],
                          "alternatives": {"input_delay": ["actuator_lag"]}})
    assert not tied["correct"] and tied["correct_or_tied"]
    later = harness.score({**base, "effects": ["input_delay", "offset"],
                           "alternatives": {"offset": ["actuator_lag"]}})
    assert not later["correct"] and not later["correct_or_tied"]
    unexplained = harness.score({**base, "verdict": "unexplained", "effects": [],
                                 "alternatives": {"input_delay": ["actuator_lag"]}})
    assert not unexplained["correct_or_tied"]
    failed = harness.score({**{k: v for k, v in base.items() if k != "verdict"},
                            "error": "RuntimeError: no static equilibrium"})  # a failed case
    assert failed["outcome"] == "error" and not failed["correct_or_tied"]
    summary = harness.summarise([tied, later])
    assert summary["library_top1_strong"]["right"] == 0
    assert summary["library_top1_or_tied_strong"] == {"right": 1, "cases": 2, "share": 0.5}


def test_out_of_library_scores_are_also_given_over_the_unabsorbable_cases(harness):
    """A creep a refitted nominal absorbs (unabsorbed 0) answered ``none`` counts against the
    strong out-of-library score but not against the unabsorbable one, as for library effects."""
    def case(label, verdict, unabsorbed):
        return harness.score({"strongest": 5.0, "gap_closed": {"F_c": 0.0},
                              "detectability": {"F_c": 5.0}, "label": label, "verdict": verdict,
                              "effects": [], "unabsorbed": {"F_c": unabsorbed}})

    summary = harness.summarise([case("creep", "none", 0.0),
                                 case("hysteresis", "unexplained", 6.0)])
    assert summary["out_of_library_unexplained_strong"]["right"] == 1
    assert summary["out_of_library_unexplained_strong"]["cases"] == 2
    assert (summary["out_of_library_unexplained_unabsorbable"]["right"],
            summary["out_of_library_unexplained_unabsorbable"]["cases"]) == (1, 1)


def test_the_reproducible_gap_median_leaves_out_only_the_unreproducible_runs(harness):
    def case(gap, reproducible):
        return harness.score({"strongest": 5.0, "gap_closed": {"F_c": gap},
                              "detectability": {"F_c": 5.0}, "label": "contact_loss",
                              "verdict": "effect", "effects": ["contact_loss"],
                              "reproducible": reproducible})

    summary = harness.summarise([case(0.9, True), case(0.8, True), case(0.02, False)])
    assert summary["gap_closed_median_named_strong"] == pytest.approx(0.8)
    assert summary["gap_closed_median_named_strong_reproducible"] == pytest.approx(0.85)


def test_the_gap_to_the_true_plant_leaves_the_measurement_noise_out(harness):
    # A nominal residual of white noise (energy n^2) plus an effect's error (energy e^2), fits in
    # per cent of the output's spread: the true plant leaves only the noise.
    rng = np.random.default_rng(3)
    output = np.sin(np.linspace(0.0, 40.0, 4000))
    noise, error = 0.05 * rng.standard_normal(4000), 0.04 * np.cos(np.linspace(0.0, 90.0, 4000))

    def fit(residual):
        return 100.0 * (1.0 - np.linalg.norm(residual) / np.linalg.norm(output - output.mean()))

    before, truth = fit(noise + error), fit(noise)
    half_fixed = fit(noise + 0.5 * error)
    assert harness.effect_gap_closed(before, truth, truth) == pytest.approx(1.0)
    assert harness.effect_gap_closed(before, before, truth) == pytest.approx(0.0)
    # Halving the error's amplitude removes 3/4 of its energy (noise and error uncorrelated).
    assert harness.effect_gap_closed(before, half_fixed, truth) == pytest.approx(0.75, abs=0.03)
    assert harness.effect_gap_closed(before, truth, before + 0.05) is None  # no gap to close


def test_rescoring_a_stored_report_keeps_every_outcome(harness, tmp_path):
    records = [harness.score({"name": f"two-mass/dead_zone/{i}", "label": "dead_zone",
                              "strongest": 5.0, "detectability": {"F_c": 5.0},
                              "verdict": "effect" if i else "none",
                              "effects": ["dead_zone"] if i else [],
                              "gap_closed": {"F_c": 0.5}, "fit_before": {"F_c": 90.0},
                              "fit_after": {"F_c": 94.0}, "ceiling": {"F_c": 95.0},
                              "excitation": "aprbs", "rate": 50.0, "duration": 20.0,
                              "inputs": 1, "outputs": ["F_c"], "snr_db": 30.0,
                              "strength": 0.5, "wall_s": 1.0}) for i in range(2)]
    settings = {"split": "tune", "command": "x", "options": {}, "workers": 1, "wall_s": 1.0,
                "platform": "p", "cases": [r["name"] for r in records]}
    harness.write_report(tmp_path / "report", records, settings, complete=True)
    import json
    stored = json.loads((tmp_path / "report.json").read_text())
    for case in stored["cases"]:  # a report written before the gap to the plant was scored
        del case["effect_gap_closed_main"]
    (tmp_path / "report.json").write_text(json.dumps(stored))
    assert harness.main(["--rescore", str(tmp_path / "report.json"), "--quiet"]) == 0
    again = json.loads((tmp_path / "report.json").read_text())
    assert [c["outcome"] for c in again["cases"]] == ["none", "dead_zone"]
    assert again["summary"]["library_top1_all"]["right"] == 1
    # (0.1^2 - 0.06^2) / (0.1^2 - 0.05^2) of the gap to the plant closed by the named case
    assert again["cases"][1]["effect_gap_closed_main"] == pytest.approx(0.0064 / 0.0075)
    assert again["settings"]["command"] == "x" and "--rescore" in again["settings"]["rescored"]
    (tmp_path / "broken.json").write_text("{")
    assert harness.main(["--rescore", str(tmp_path / "broken.json"), "--quiet"]) == 2


def test_named_cases_run_instead_of_a_split_and_a_bad_name_is_one_line(harness, capsys):
    """``--names`` takes cases already looked at (a record's misses re-run with newer code);
    a malformed name is refused with what was expected, never a traceback."""
    arguments = harness.parse_arguments(["--names", "two-mass/offset/129", "--quick"])
    assert [s.name for s in arguments.specs] == ["two-mass/offset/129"]
    with pytest.raises(SystemExit):
        harness.parse_arguments(["--names", "two-mass/offset"])
    assert "expected FAMILY/LABEL/SEED" in capsys.readouterr().err
