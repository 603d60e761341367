"""``panto rig``: run on the virtual test bed, preview a profile, check a dataset, refuse bad input."""
from pathlib import Path

import numpy as np
import pytest

from panto.cli import main
from panto.rig.dataset import read_dataset

PROFILES = Path(__file__).resolve().parent.parent / "rig" / "profiles"


@pytest.mark.parametrize("profile", sorted(p.name for p in PROFILES.glob("*.json")
                                            if not p.name.endswith(".csv.json")))
def test_every_shipped_profile_loads_and_previews(profile, tmp_path, capsys):
    assert main(["rig", "profile", str(PROFILES / profile), "--out", str(tmp_path)]) == 0
    pngs = list(tmp_path.glob("*.png"))
    assert len(pngs) == 1 and pngs[0].stat().st_size > 10_000


def test_rig_run_on_the_virtual_test_bed_then_check(project_fmus, tmp_path, capsys):
    fmu = str(project_fmus["Pantograph.fmu"].path)
    code = main(["rig", "run", str(PROFILES / "aprbs_training.json"), "--duration", "1.0",
                 "--out", str(tmp_path / "runs"), "--fmu", fmu, "--seed", "2"])
    assert code == 0
    run = tmp_path / "runs" / "run_0001"
    for name in ("run.csv", "run.csv.json", "run.parquet", "run.mat", "truth.csv"):
        assert (run / name).is_file()
    csv, parquet, mat = (read_dataset(run / n) for n in ("run.csv", "run.parquet", "run.mat"))
    for name in csv.names:
        np.testing.assert_array_equal(csv[name], parquet[name])
        np.testing.assert_array_equal(csv[name], mat[name])
    assert main(["rig", "check", str(run)]) == 0
    assert "500 samples at 500 Hz" in capsys.readouterr().out
    # A second run goes into a new numbered folder, never over the first.
    assert main(["rig", "run", str(PROFILES / "sine_1hz.json"), "--duration", "0.2",
                 "--out", str(tmp_path / "runs"), "--fmu", fmu, "--imperfections", "none"]) == 0
    assert (tmp_path / "runs" / "run_0002" / "run.csv").is_file()


def test_rig_commands_refuse_bad_input_with_a_clear_message(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text('{"duration": 1, "limits": {"motor_min": 0.1, "motor_max": -0.1, '
                   '"safe_pressure": 4}, "motor": {"offset": 0}, "pressure": {"offset": 4}}')
    assert main(["rig", "profile", str(bad), "--out", str(tmp_path)]) == 65
    assert "motor_max" in capsys.readouterr().err
    broken = tmp_path / "broken.csv"
    broken.write_text("time [s],force [N]\n0.0,1.0\n0.002,nan\n0.001,2.0\n")
    assert main(["rig", "check", str(broken), "--any-channels"]) == 65
    assert "broken.csv" in capsys.readouterr().err
    assert main(["rig", "run", str(PROFILES / "sine_1hz.json"), "--interface", "virtual",
                 "--channel", "x", "--folder", str(tmp_path / "r")]) == 2
    assert "--io" in capsys.readouterr().err
