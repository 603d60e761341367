"""Parameter sets as data, the oscillators' friction, and the command line."""
import json

import numpy as np
import pytest

from panto.fmu_src.models import Model, default_parameters, load_parameters
from panto.fmu_src.parameters import ParameterError
from panto.cli import main
from panto.rig.dataset import read_dataset
from panto.rig.profiles import load_profile


def test_parameter_file_round_trip_keeps_values_units_and_provenance(tmp_path):
    params = default_parameters("Pantograph").with_values(k_ph=50000.0, m_c=7.5)
    path = params.save(tmp_path / "p.json")
    data = json.loads(path.read_text())
    assert data["parameters"]["m1"]["unit"] == "kg"
    assert "Table 4.1" in data["parameters"]["m1"]["provenance"]
    loaded = load_parameters(path)
    assert loaded.model == "Pantograph"
    assert np.array_equal(loaded.vector(), params.vector())


@pytest.mark.parametrize("changes,message", [
    ({"m1": -1.0}, "'m1' = -1 kg is outside"),
    ({"k": float("nan")}, "not finite"),
    ({"unilateral_contact": 0.5}, "switch"),
    ({"no_such": 1.0}, "unknown parameter"),
], ids=["negative-mass", "nan", "switch", "unknown"])
def test_invalid_values_are_refused_with_a_clear_error(changes, message):
    with pytest.raises(ParameterError, match=message):
        default_parameters("Pantograph").with_values(changes)


def test_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"model": "Pantograph", "parameters": {"m_c": {"value": -3}}}')
    with pytest.raises(ParameterError, match="bad.json.*m_c"):
        load_parameters(bad)
    other = tmp_path / "other.json"
    default_parameters("TwoMass").save(other)
    with pytest.raises(ParameterError, match="for model 'TwoMass'"):
        load_parameters(other, "Pantograph")


def test_a_linkage_that_cannot_close_is_refused():
    with pytest.raises(ParameterError, match="cannot close"):
        Model("Pantograph", {"l3": 5.0})


def test_coulomb_friction_acts_against_the_velocity():
    """eq. 2.35 smoothed: the friction force on mass 1 is -F_f tanh(v / v_eps)."""
    plain = Model("TwoMass")
    rough = Model("TwoMass", {"F_f1": 20.0, "v_eps": 1e-3})
    x = np.array([0.0, 0.0, 0.2, 0.0])  # mass 1 moving up at 0.2 m/s
    difference = rough.derivatives(x, 0.0, 0.0) - plain.derivatives(x, 0.0, 0.0)
    assert difference[2] == pytest.approx(-20.0 * np.tanh(200.0) / 15.0)
    assert np.allclose(difference[[0, 1, 3]], 0.0)


def test_two_mass_linearisation_is_the_thesis_state_space():
    """Eq. 2.33 (with the contact spring's -k_E/m2 on x2, which the printed matrix omits)."""
    p = default_parameters("TwoMass")
    m1, m2, k1, k2, c1, c2, kE = (p[n] for n in ("m1", "m2", "k1", "k2", "c1", "c2", "k_E"))
    lin = Model("TwoMass").linearise(0.0, 0.0)
    order = [0, 2, 1, 3]  # ours: [x1, x2, v1, v2]; thesis: [x1, v1, x2, v2]
    A = lin.A[np.ix_(order, order)]
    expected = np.array([
        [0, 1, 0, 0],
        [-(k1 + k2) / m1, -(c1 + c2) / m1, k2 / m1, c2 / m1],
        [0, 0, 0, 1],
        [k2 / m2, c2 / m2, -(k2 + kE) / m2, -c2 / m2]])
    np.testing.assert_allclose(A, expected, rtol=1e-12)
    assert lin.B[order][3, 0] == pytest.approx(kE / m2)  # wire pushes the head up


def test_cli_linearise_writes_json(tmp_path, capsys):
    out = tmp_path / "lin.json"
    assert main(["linearise", "--eta", "2.0", "--p", "4.0", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["outputs"]["F_c"] == pytest.approx(81.1, abs=0.1)
    assert len(result["A"]) == 6
    assert "modes" in capsys.readouterr().out


def test_cli_reports_bad_input_without_a_traceback(tmp_path, capsys):
    assert main(["linearise", "--eta", "9.0"]) == 65
    assert "reachable" in capsys.readouterr().err


def test_quick_demo_runs_every_step_and_writes_the_report(tmp_path):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["status"] for s in summary["steps"]] == ["ok"] * 7
    assert all(f["valid"] for f in summary["fmus"]["fmus"])
    for label in ("training", "validation"):
        folder = tmp_path / summary["rig"]["runs"][label]["folder"]
        for name in ("run.csv", "run.parquet", "run.mat", "truth.csv"):
            assert (folder / name).is_file()
        fits = summary["rig"]["nominal_model_fit_percent"][label]
        # The nominal model explains much of the cross-bar motion but not all: the rig's
        # imperfections (contact loss, friction, bar inertia, bellow lag) are on.
        assert 20.0 < fits["Pantograph"]["y_cb"] < 99.0
        # Linearised and nonlinear FMUs agree closely on the same small-signal inputs.
        assert abs(fits["Pantograph"]["y_cb"] - fits["PantographLinear"]["y_cb"]) < 5.0
        # The video: the LED aligns the track with the run to within one camera frame of the
        # camera's truth, and the tracked cross bar follows the lasers to a millimetre or so.
        video = summary["video"]["runs"][label]
        assert video["sync_confidence"] > 0.9
        assert video["sync_error_samples"] == 0  # exact on the 500 Hz grid
        assert video["video_vs_laser"]["std_mm"] < 2.0
        merged = read_dataset(tmp_path / video["merged_dataset"])
        assert "video_cross_bar_y" in merged.names and "force" in merged.names
    physical = summary["identification"]["physical"]
    identified, nominal = physical["fit_validation"], physical["nominal_fit_validation"]
    # Fitted on the training run, the physical model predicts the withheld run better than the
    # nominal parameters do (free run, both outputs).
    assert np.mean(list(identified.values())) > np.mean(list(nominal.values())) + 5.0
    assert (tmp_path / physical["parameter_file"]).is_file()
    rows = summary["identification"]["comparison"]["rows"]
    assert {r["structure"] for r in rows} >= {"physical-linear", "blackbox-4"}
    diagnosis = summary["diagnosis"]
    assert diagnosis["verdict"] in ("effect", "unexplained", "none")
    assert all(diagnosis["fit_after"][o] >= diagnosis["fit_before"][o] - 1e-9
               for o in diagnosis["fit_before"])
    assert [s["effect"] for s in diagnosis["steps"]] == diagnosis["effects"]
    # The rig's truth beside the verdict: the default rig's friction and contact loss are on,
    # and a row is marked named exactly when the diagnosis accepted its library effect.
    hidden = {r["imperfection"]: r for r in diagnosis["rig_truth"]}
    assert hidden["hinge_friction_torque"]["value"] == 20.0
    assert hidden["unilateral_contact"]["effect"] == "contact_loss"
    assert all(r["named"] == (r["effect"] in diagnosis["effects"]) for r in hidden.values())
    doe = summary["doe"]
    assert doe["det_ratio_per_parameter"] > 1.0  # the design beats an APRBS of equal length
    load_profile(tmp_path / doe["files"]["profile"])  # the rig accepts the designed run
    cosim = {row["statistic"]: row for row in summary["cosim"]["statistics"]}
    assert set(cosim) == {"mean", "std", "stat_max", "stat_min", "max", "min", "uplift_max_mm",
                          "loss_pct"}
    assert all(row["target"] is not None for row in cosim.values())
    # The mean contact force along the line stays near the static force the pressure sets.
    assert cosim["mean"]["value"] == pytest.approx(summary["cosim"]["static_force_N"], rel=0.15)
    report = (tmp_path / "report.html").read_text()
    assert "EN 50318" in report and "physical-linear" in report
    assert "What the virtual rig hid" in report
    assert report.count("data:image/png;base64") >= 10
    # the overview picture gathers the six panels a failed step did not leave out
    from matplotlib.image import imread

    assert "overview: six of the plots below" in report
    assert imread(tmp_path / "overview.png").shape[0] > 3 * 4.6 * 90 - 2


def test_a_failing_demo_step_is_recorded_and_the_others_still_run(tmp_path, monkeypatch):
    import panto.demo as demo

    def good(state, progress):
        state["first"] = True
        return {"value": 1}

    def bad(state, progress):
        raise ValueError("the valve is stuck at 7 bar")

    monkeypatch.setattr(demo, "_steps", lambda: (
        demo.Step("one", "first", good), demo.Step("two", "second", bad),
        demo.Step("three", "needs the second", good, ("missing",)),
        demo.Step("four", "independent", good, ("first",))))
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 1  # non-zero at the end
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["status"] for s in summary["steps"]] == ["ok", "failed", "skipped", "ok"]
    assert summary["failed_steps"] == ["two", "three"]
    assert summary["four"] == {"value": 1}
    assert "valve is stuck" in (tmp_path / "report.html").read_text()


def test_demo_states_a_friction_found_as_pressure_as_the_hinge_torque():
    from types import SimpleNamespace

    from panto.demo_analysis import _hinge_torque

    step = SimpleNamespace(parameters={"coulomb_friction:p": -0.05},
                           std={"coulomb_friction:p": 0.01})
    # the bellow torque is k_p p on the lower arm: 0.05 bar of it is 0.05 k_p N m
    assert _hinge_torque(step, {"k_p": 258.0}) == pytest.approx([12.9, 2.58])
    assert _hinge_torque(SimpleNamespace(parameters={}, std={}), {"k_p": 258.0}) is None
