"""The virtual test bed in real time: emulator thread + plant against the wall clock.

No timing is asserted (that is benchmarks/rig_loop_timing.py): a real-time run on a shared
machine may legitimately end with a drive fault, but it must end cleanly, with the fault named
and everything recorded on disk.
"""
import threading

import can
import numpy as np
import pytest

from panto.rig.can_protocol import ErrorCode
from panto.rig.dataset import read_dataset
from panto.rig.drive import LinearMotorDriver
from panto.rig.clock import RealClock
from panto.rig.imperfections import RigImperfections
from panto.rig.profiles import profile_from_dict
from panto.rig.realtime import (REALTIME_DRIVE_SETTINGS, RealtimeOptions, drive_parameters,
                          run_virtual_profile_realtime, serve_emulator)

_DRIVE_CODES = {int(code) for code in ErrorCode}


def _profile(duration):
    return profile_from_dict({
        "name": "realtime-smoke", "duration": duration, "seed": 3,
        "limits": {"motor_min": -0.1, "motor_max": 0.1, "safe_pressure": 4.0},
        "motor": {"offset": 0.0, "signals": [{"kind": "sine", "frequency": 2.0,
                                              "amplitude": 0.005}]},
        "pressure": {"offset": 4.0, "signals": []},
    })


def test_a_real_time_run_completes_or_stops_with_a_named_drive_fault(project_fmus, tmp_path):
    profile = _profile(0.6)
    folder = tmp_path / "run"
    result = run_virtual_profile_realtime(profile, fmu_path=project_fmus["Pantograph.fmu"].path,
                                          folder=folder, imperfections=RigImperfections.none())
    data = read_dataset(folder)  # readable (schema-checked) whatever happened
    assert data.metadata.status.startswith(result.status)  # the recorder may add the instant
    assert np.all(np.diff(data.time) > 0)
    if result.success:
        assert data.time.size == profile.sample_count
        assert np.all(data["drive_error"] == 0)
    else:  # a stall this machine could not hide from the drive: named, and stopped safely
        assert result.status.startswith("aborted: ")
        assert result.fault_code in _DRIVE_CODES, result.status
        assert ("0x" in result.status) or ErrorCode(result.fault_code).name in result.status
    # While the drive was in operation the slider stayed within the following-error limit.
    running = data["drive_state"] == 8
    lag = np.abs(data["motor_position"] - data["motor_command"])[running]
    assert np.all(lag < 0.030)
    assert np.isfinite(data["force"]).all() and np.isfinite(data["pressure"]).all()
    metadata = data.metadata.truth
    assert metadata["drive"]["stream_delay_periods"] == REALTIME_DRIVE_SETTINGS[
        "stream_delay_periods"]


def test_lenient_drive_timing_is_the_default_and_overrides_go_on_top():
    faithful = drive_parameters({}, lenient_timing=False)
    lenient = drive_parameters({"position_loop_bandwidth_hz": 30.0})
    assert faithful.stream_delay_periods == 1.5 and faithful.timebase_correction == 0.0
    assert lenient.stream_delay_periods == REALTIME_DRIVE_SETTINGS["stream_delay_periods"]
    assert lenient.stream_period_range == REALTIME_DRIVE_SETTINGS["stream_period_range"]
    assert lenient.position_loop_bandwidth_hz == 30.0
    with pytest.raises(ValueError, match="bandwith"):
        drive_parameters({"bandwith": 30.0})
    with pytest.raises(ValueError, match="reply_timeout_cycles"):
        RealtimeOptions(reply_timeout_cycles=0)


def test_served_emulator_answers_an_external_master_on_the_bus(project_fmus, request):
    """serve_emulator on a shared bus: a driver (here in this process) starts and stops it."""
    channel = f"serve-emulator-{request.node.name}"
    stop, serving = threading.Event(), threading.Event()
    outcome = {}

    def serve():
        with can.Bus(interface="virtual", channel=channel) as bus:
            outcome["summary"] = serve_emulator(bus, fmu_path=project_fmus["Pantograph.fmu"].path,
                                                stop_event=stop, duration=30.0,
                                                progress=lambda line: serving.set())

    server = threading.Thread(target=serve, daemon=True)
    with can.Bus(interface="virtual", channel=channel) as master:
        server.start()
        try:
            assert serving.wait(timeout=20), "the emulator did not start serving"
            driver = LinearMotorDriver(master, clock=RealClock(), reply_timeout_cycles=250)
            assert driver.start().main_state == 8
            assert driver.disable().main_state == 2
        finally:
            stop.set()
            server.join(timeout=10)
    summary = outcome["summary"]
    assert summary.stopped_by == "stop_event" and summary.success
    assert summary.main_state == 2 and summary.error_code == 0
    assert summary.plant_samples > 0  # the plant was stepped by the drive's listener
