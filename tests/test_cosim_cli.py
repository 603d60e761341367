"""``panto cosim`` (panto/commands_cosim.py) and the rig sequence (panto.catenary_cosim.rig_sequence)."""
import dataclasses
import json

import numpy as np
import pytest

from panto.catenary_cosim.lines import LINE_DIRECTORY, load_line
from panto.catenary_cosim.rig_sequence import make_rig_sequence, periodic_sequence, resample_periodic
from panto.catenary_cosim.statistics import STATISTIC_KEYS
from panto.cli import main


@pytest.fixture(scope="module")
def two_spans(tmp_path_factory):
    data = json.loads((LINE_DIRECTORY / "en50318-2002.json").read_text())
    data["name"] = "two-spans"
    data["items"]["spans"]["value"] = 2
    data["items"]["analysed_spans"]["value"] = [2, 2]
    path = tmp_path_factory.mktemp("lines") / "two_spans.json"
    path.write_text(json.dumps(data))
    return path


FAST = ["--time-step", "5e-4", "--element-length", "2"]


def test_run_writes_statistics_json_series_and_plots(tmp_path, two_spans, project_fmus, capsys):
    fmu = str(project_fmus["TwoMass.fmu"].path)
    out, summary = tmp_path / "out", tmp_path / "stats.json"
    code = main(["cosim", "--line", str(two_spans), "--speed", "250", "--pantograph",
                 "en50318-2002", "--fmu", fmu, "--out", str(out), "--json", str(summary),
                 *FAST])
    assert code == 0
    document = json.loads(summary.read_text())
    assert set(STATISTIC_KEYS) <= set(document)
    assert all(isinstance(document[key], float) for key in STATISTIC_KEYS)
    settings = document["settings"]
    assert settings["speed_kmh"] == 250.0 and settings["line"] == "two-spans"
    assert settings["pantograph"]["name"] == "en50318-2002"
    assert settings["fmu"] == fmu
    assert (out / "two-spans_250kmh.csv").is_file()
    assert (out / "two-spans_250kmh_force.png").is_file()
    printed = capsys.readouterr()
    assert "mean contact force" in printed.out and "100 %" in printed.err  # statistics and progress


def test_run_of_a_user_fmu_by_variable_names(tmp_path, two_spans, project_fmus):
    summary = tmp_path / "user.json"
    code = main(["cosim", "--line", str(two_spans), "--speed", "200", "--fmu",
                 str(project_fmus["TwoMass.fmu"].path), "--height-input", "eta",
                 "--force-output", "F_c", "--height-offset", "-5.3", "--json", str(summary),
                 *FAST])
    assert code == 0
    document = json.loads(summary.read_text())
    assert document["settings"]["eta_offset_m"] == -5.3
    assert document["mean"] > 0.0


@pytest.mark.parametrize("arguments, message", [
    (["--line", "atlantis", "--speed", "250"], "unknown line 'atlantis'"),
    (["--speed", "0"], "speed must be a positive"),
    (["--speed", "500"], "wave speed"),
    (["--pantograph", "flying"], "unknown pantograph"),
    (["--speed", "250", "--height-input", "height"], "valid input names: eta, p"),
    (["--speed", "250", "--force-output", "force"], "F_c"),
], ids=["line", "speed-zero", "speed-above-wave", "pantograph", "no-input", "no-output"])
def test_bad_input_gives_a_clear_message(arguments, message, two_spans, project_fmus, capsys):
    if "--line" not in arguments:
        arguments = ["--line", str(two_spans), *arguments]
    if "--pantograph" not in arguments:
        arguments = [*arguments, "--fmu", str(project_fmus["TwoMass.fmu"].path)]
    if "--speed" not in arguments:
        arguments = [*arguments, "--speed", "250"]
    code = main(["cosim", *arguments, *FAST])
    assert code == 65
    error = capsys.readouterr().err
    assert error.startswith("panto cosim: error:") and message in error


def test_periodic_sequence_recovers_a_known_periodic_signal():
    # two spans of a known periodic shape plus a slow drift: the drift is removed and the
    # shape comes back, zero-mean and exactly periodic
    length = 60.0
    x = np.linspace(0.0, 3 * length, 9001)
    shape = 0.02 * np.sin(2 * np.pi * x / length) + 0.005 * np.cos(6 * np.pi * x / length)
    drift = 1e-4 * x
    s, displacement, info = periodic_sequence(x, 5.3 + shape + drift,
                                              [(60.0, 120.0), (120.0, 180.0)])
    expected = 0.02 * np.sin(2 * np.pi * s / length) + 0.005 * np.cos(6 * np.pi * s / length)
    np.testing.assert_allclose(displacement, expected - expected.mean(), atol=1e-6)
    assert info["drift_m"] == pytest.approx(1e-4 * length, rel=1e-3)
    values = resample_periodic(displacement, 0.72, 500.0)
    assert values.size == 360 and abs(values.mean()) < 1e-12
    time = np.arange(360) / 500.0
    reference = 0.02 * np.sin(2 * np.pi * time / 0.72) + 0.005 * np.cos(6 * np.pi * time / 0.72)
    np.testing.assert_allclose(values, reference - reference.mean(), atol=2e-5)


def test_rig_sequence_file_format(tmp_path, project_fmus):
    from panto.fmu_src.response import TimeResponse

    line = dataclasses.replace(load_line("thesis-60m"), spans=3, analysed_spans=(2, 2))
    from panto.catenary_cosim.pantographs import pantograph_setup

    setup = pantograph_setup("physical").with_fmu(project_fmus["Pantograph.fmu"].path)
    path = make_rig_sequence(tmp_path / "catenary.csv", line=line, pantograph=setup,
                             time_step=4e-4, element_length=2.0)
    assert path.read_text().splitlines()[0] == "time [s],contact_wire_displacement [m]"
    sequence = TimeResponse.from_csv(path)
    assert len(sequence) == 360
    np.testing.assert_allclose(np.diff(sequence.time), 1 / 500.0, rtol=1e-9)
    values = sequence["contact_wire_displacement"]
    assert abs(values.mean()) < 1e-12 and 0.005 < np.ptp(values) < 0.2
    metadata = json.loads((tmp_path / "catenary.csv.json").read_text())
    assert metadata["period"] == pytest.approx(0.72)
    assert metadata["units"]["contact_wire_displacement"] == "m"
    assert metadata["speed_kmh"] == 300.0 and metadata["pantograph"] == "physical"
