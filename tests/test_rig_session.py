"""Whole rig runs on the virtual test bed: real CAN frames, the drive emulator, the pantograph FMU."""
import json

import numpy as np
import pytest

from panto.rig.can_protocol import ErrorCode
from panto.rig.dataset import read_dataset
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import profile_from_dict
from panto.rig.virtual import run_virtual_profile


@pytest.fixture(scope="module")
def pantograph_fmu(project_fmus):
    return project_fmus["Pantograph.fmu"].path


def _profile(motor_signals, *, duration=4.0, limiter=True, reference_filter=False):
    return profile_from_dict({
        "name": "test", "duration": duration, "seed": 7,
        "limits": {"motor_min": -0.1, "motor_max": 0.1, "safe_pressure": 4.0,
                   "pressure_min": 3.4, "pressure_max": 6.0},
        "conditioning": {"limiter": limiter, "reference_filter": reference_filter,
                         "blend_time_constant": 0.05},
        "motor": {"offset": 0.0, "signals": motor_signals},
        "pressure": {"offset": 4.0, "signals": [
            {"kind": "steps", "count": 1, "height": 0.8, "hold_time": 2.0, "start": 1.0}]},
    })


def test_an_aprbs_run_completes_and_records_what_the_rig_did(pantograph_fmu, tmp_path):
    profile = _profile([{"kind": "aprbs", "std": 0.02, "hold_min": 0.2, "hold_max": 0.8}])
    result = run_virtual_profile(profile, fmu_path=pantograph_fmu, folder=tmp_path / "run",
                                 imperfections=RigImperfections(), seed=1)
    assert result.success, result.status
    data = read_dataset(tmp_path / "run")
    assert data.time.size == profile.sample_count
    assert np.all(data["drive_state"] == 8)  # operation enabled throughout: no stream error
    assert np.all(data["drive_error"] == 0)
    # The limiter held every 250 Hz command change to 5 mm.
    commands = data["motor_command"][::2]
    assert np.max(np.abs(np.diff(commands))) <= 0.005 + 1e-12
    assert np.ptp(commands) > 0.02  # and the motor really moved
    # The slider follows the command (delayed by the stream and the 20 Hz loop) within mm.
    lag = data["motor_position"] - data["motor_command"]
    assert np.max(np.abs(lag)) < 0.03
    assert np.sqrt(np.mean(lag**2)) < 0.01
    # The pressure loop follows the 0.8 bar step (through the valve's first-order lag).
    settled = (data.time > 2.6) & (data.time < 3.0)
    assert np.mean(data["pressure"][settled]) == pytest.approx(4.8, abs=0.1)
    # Force sensor: the pantograph presses on the bar (mean of order of the static 81 N).
    assert 40 < np.mean(data["force"]) < 160
    metadata = json.loads((tmp_path / "run" / "run.csv.json").read_text())["metadata"]
    assert metadata["source"] == "emulator" and metadata["status"] == "complete"
    assert metadata["truth"]["imperfections"]["bar_mass"] == 1.5
    assert metadata["profile"]["name"] == "test"
    # The set-up the identification needs (eta = motor_zero_height + slider) is a known fact.
    assert metadata["extra"]["rig_setup"]["motor_zero_height"] == 2.0
    assert metadata["extra"]["rig_setup"]["position_latency"] == pytest.approx(0.005)


def test_a_step_the_limiter_would_catch_trips_the_drive_and_the_run_stops_safely(
        pantograph_fmu, tmp_path):
    step = [{"kind": "steps", "count": 1, "height": 0.05, "hold_time": 5.0, "start": 1.0,
             "descend": False}]
    with_limiter = run_virtual_profile(_profile(step, duration=2.0), fmu_path=pantograph_fmu,
                                       folder=tmp_path / "limited",
                                       imperfections=RigImperfections.none())
    assert with_limiter.success, with_limiter.status

    result = run_virtual_profile(_profile(step, duration=2.0, limiter=False),
                                 fmu_path=pantograph_fmu, folder=tmp_path / "tripped",
                                 imperfections=RigImperfections.none())
    assert not result.success
    assert result.fault_code == ErrorCode.FOLLOWING_ERROR
    assert "0x0B" in result.status and "position lag" in result.status
    assert "bellow at safe pressure" in result.status
    data = read_dataset(tmp_path / "tripped")
    # Everything up to the fault is on disk: the run went past the step at 1 s, then stopped.
    fault_time = float(result.status.split("t = ")[1].split(" s")[0])
    assert 1.0 < fault_time < 1.2
    assert data.time[0] == 0.0 and np.all(np.diff(data.time) > 0)
    assert data.time[-1] >= fault_time
    assert np.any(data["drive_state"] == 4)  # the drive's error state was recorded
    metadata = json.loads((tmp_path / "tripped" / "run.csv.json").read_text())["metadata"]
    assert metadata["status"].startswith("aborted: drive error 0x0B")
    # The bellow was driven to the safe pressure after the fault.
    assert abs(data["pressure"][-1] - 4.0) < 0.1


def test_a_silent_drive_is_detected_and_nothing_recorded_is_lost(pantograph_fmu, tmp_path,
                                                                  monkeypatch):
    from panto.rig import virtual as virtual

    original = virtual.DriveEmulator

    class DyingDrive(original):
        """A drive whose cable is cut 1.5 s into the run."""

        def process_pending(self):
            if self.time > 1.5:
                self.silent = True
            return super().process_pending()

    monkeypatch.setattr(virtual, "DriveEmulator", DyingDrive)
    profile = _profile([{"kind": "sine", "frequency": 1.0, "amplitude": 0.01}], duration=3.0)
    result = run_virtual_profile(profile, fmu_path=pantograph_fmu, folder=tmp_path / "run",
                                 imperfections=RigImperfections.none())
    assert result.fault_code == ErrorCode.MISSING_REPLIES
    data = read_dataset(tmp_path / "run")
    assert data.time[-1] > 1.5
    assert np.isfinite(data["force"]).all()


def test_a_run_never_overwrites_an_earlier_one(pantograph_fmu, tmp_path):
    profile = _profile([], duration=0.2)
    run_virtual_profile(profile, fmu_path=pantograph_fmu, folder=tmp_path / "run",
                        imperfections=RigImperfections.none())
    before = (tmp_path / "run" / "run.csv").read_bytes()
    with pytest.raises(FileExistsError, match="never overwrites"):
        run_virtual_profile(profile, fmu_path=pantograph_fmu, folder=tmp_path / "run",
                            imperfections=RigImperfections.none())
    assert (tmp_path / "run" / "run.csv").read_bytes() == before


def test_the_truth_beside_a_virtual_run_shares_its_time_base(pantograph_fmu, tmp_path):
    """truth.csv: the bar really is where the drive says (no robot mode), on the run's time axis."""
    profile = _profile([{"kind": "sine", "frequency": 2.0, "amplitude": 0.01}], duration=1.0)
    result = run_virtual_profile(profile, fmu_path=pantograph_fmu, folder=tmp_path / "run",
                                 imperfections=RigImperfections.none())
    assert result.success
    data = read_dataset(tmp_path / "run")
    truth = read_dataset(tmp_path / "run" / "truth.csv", required=())
    assert truth.time[0] < 0.0  # the drive's start-up came first
    at_run = np.searchsorted(truth.time, data.time - 1e-6)  # same instants, up to round-off
    np.testing.assert_allclose(truth.time[at_run], data.time, atol=1e-9)
    # Ideal sensors: the force channel is the true contact force at the same instants ...
    np.testing.assert_allclose(data["force"], truth["contact_force"][at_run], atol=1e-9)
    # ... and the drive's reported position (0.1 um units) is the slider's true position.
    np.testing.assert_allclose(data["motor_position"][2:], truth["slider_position"][at_run][2:],
                               atol=2e-3)
