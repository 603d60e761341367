"""The CAN linear-motor driver against the drive emulator, on python-can's virtual bus.

Everything runs in lock step on a simulated clock: the emulator answers when the clock is about to
move on (a clock hook), so no test depends on wall-clock timing.
"""
import math
import struct
import threading

import can
import cantools
import numpy as np
import pytest
from scipy import signal

from panto.rig import can_protocol as proto
from panto.rig.clock import RealClock, SimulatedClock, Ticker
from panto.rig.drive import BusFault, DriveFault, LinearMotorDriver, ProtocolError, RigError, open_bus
from panto.rig.drive_emulator import DriveEmulator

T = 0.004  # stream period of the thesis' rig (250 Hz)
STEP_LIMIT = 0.005  # the rig's limiter: 5 mm per sample


class Rig:
    """Driver and emulated drive on one virtual channel, pumped by a simulated clock."""

    def __init__(self, channel, *, driver_options=None, **emulator_options):
        self.clock = SimulatedClock(start=10.0)
        self.master_bus = can.Bus(interface="virtual", channel=channel)
        self.drive_bus = can.Bus(interface="virtual", channel=channel)
        self.analyser_bus = can.Bus(interface="virtual", channel=channel)
        self.samples = []
        self.emulator = DriveEmulator(self.drive_bus, clock=self.clock,
                                      listener=lambda t, x, v: self.samples.append((t, x, v)),
                                      **emulator_options)
        self.driver = LinearMotorDriver(self.master_bus, clock=self.clock,
                                        **(driver_options or {}))
        self.clock.add_hook(self.emulator.process_pending)
        self.ticker = None

    def start(self):
        feedback = self.driver.start()
        self.ticker = Ticker(self.clock, T)
        return feedback

    def cycle(self, position):
        """One stream cycle: wait for the deadline, check the replies, send setpoint + SYNC."""
        self.ticker.wait()
        self.driver.check()
        self.driver.stream(position)

    def recorded_frames(self):
        frames = []
        while (frame := self.analyser_bus.recv(timeout=0)) is not None:
            frames.append(frame)
        return frames

    def close(self):
        for bus in (self.master_bus, self.drive_bus, self.analyser_bus):
            bus.shutdown()


@pytest.fixture
def make_rig(request):
    rigs = []

    def factory(**options):
        rig = Rig(f"{request.node.name}-{len(rigs)}", **options)
        rigs.append(rig)
        return rig

    yield factory
    for rig in rigs:
        rig.close()


def limited_aprbs(rng, n, *, start, sigma, hold=(10, 40)):
    """APRBS levels start + N(0, sigma), held `hold` samples, through a 5 mm/sample limiter.

    The first sample is `start` (a stream starts where the slider is).
    """
    levels = np.empty(n)
    position, level, left = start, start, 0
    for k in range(n):
        levels[k] = position
        if left == 0:
            level, left = start + rng.normal(0.0, sigma), int(rng.integers(*hold))
        left -= 1
        position += float(np.clip(level - position, -STEP_LIMIT, STEP_LIMIT))
    return levels


# ---- the DBC file and the protocol helpers -------------------------------------------------

def test_dbc_parses_and_has_the_protocol_frames():
    db = cantools.database.load_file(str(proto.DBC_PATH), strict=True)
    layout = {m.name: (m.frame_id, m.length) for m in db.messages}
    assert layout == {"NMT": (0x000, 2), "SYNC": (0x080, 0), "RxPDO1": (0x23F, 8),
                      "TxPDO1": (0x1BF, 8), "TxPDO2": (0x2BF, 8), "TxPDO3": (0x3BF, 4)}
    for message in db.messages:
        for sig in message.signals:
            assert sig.byte_order == "little_endian", (message.name, sig.name)
    position = db.get_message_by_name("TxPDO1").get_signal_by_name("ActualPosition")
    assert (position.scale, position.unit, position.is_signed, position.length) == (1e-7, "m",
                                                                                     True, 32)
    current = db.get_message_by_name("TxPDO2").get_signal_by_name("DemandCurrent")
    assert (current.scale, current.unit) == (1e-3, "A")


ROUND_TRIPS = {
    "NMT": {"NmtCommand": 1, "NmtNodeId": 63},
    "SYNC": {},
    "RxPDO1": {"ControlWord": 0x3F, "MotionCommandCount": 9, "MotionCommandSubId": 0,
               "MotionCommandMasterId": 3, "TargetPosition": -0.1234567},
    "TxPDO1": {"StatusWord": 0x2C01, "StateLowByte": 9, "MainState": 8,
               "ActualPosition": 0.2000001},
    "TxPDO2": {"DemandPosition": 1.5, "DemandCurrent": -12.345},
    "TxPDO3": {"WarnWord": 0x10, "LoggedErrorCode": 0x0B},
}


@pytest.mark.parametrize("name", sorted(ROUND_TRIPS))
@pytest.mark.parametrize("node_id", [63, 5])
def test_every_frame_round_trips(name, node_id):
    values = ROUND_TRIPS[name]
    frame = proto.encode_frame(name, values, node_id=node_id)
    decoded_name, decoded = proto.decode_frame(frame, node_id=node_id)
    assert decoded_name == name
    assert decoded.keys() == values.keys()
    for key, value in values.items():
        assert decoded[key] == pytest.approx(value, abs=1e-12), key


def test_setpoint_bytes_are_little_endian_fields():
    """RxPDO1 = u16 control word, u16 header (master, sub, count), i32 position in 0.1 um."""
    frame = proto.setpoint_frame(0x003F, node_id=63, master_id=3, sub_id=0, count=7,
                                 position=0.0123456)
    assert frame.arbitration_id == 0x23F
    assert bytes(frame.data) == struct.pack("<HHi", 0x003F, 0x0307, 123456)
    reply = can.Message(arbitration_id=0x1BF, is_extended_id=False,
                        data=struct.pack("<HHi", 0x0401, 0x0805, -20))
    name, values = proto.decode_frame(reply, node_id=63)
    assert (name, values["MainState"], values["StateLowByte"]) == ("TxPDO1", 8, 5)
    assert values["ActualPosition"] == pytest.approx(-2e-6)


def test_frame_ids_follow_the_node_and_foreign_frames_are_ignored():
    ids = proto.FrameIds.for_node(5)
    assert (ids.rxpdo1, ids.txpdo1, ids.txpdo2, ids.txpdo3) == (0x205, 0x185, 0x285, 0x385)
    other = proto.encode_frame("TxPDO1", ROUND_TRIPS["TxPDO1"], node_id=63)
    assert proto.decode_frame(other, node_id=5) is None
    with pytest.raises(ValueError, match="node_id"):
        proto.FrameIds.for_node(128)
    short = can.Message(arbitration_id=0x1BF, data=b"\x00\x00", is_extended_id=False)
    with pytest.raises(ValueError, match="TxPDO1.*2 data bytes, expected 8"):
        proto.decode_frame(short, node_id=63)
    with pytest.raises(ValueError, match="finite"):
        proto.setpoint_frame(0x3F, position=math.nan)


def test_error_codes_have_meanings():
    assert proto.describe_error(0x0B) == "following error: position lag always too big"
    for code in (0x82, 0x83, 0x84, 0x85, 0x86):
        assert "stream" in proto.describe_error(code) or "state" in proto.describe_error(code)
    assert "overflow" in proto.describe_error(0x82) and "underflow" in proto.describe_error(0x83)
    assert "too fast" in proto.describe_error(0x84) and "too slow" in proto.describe_error(0x85)
    assert proto.describe_error(proto.ErrorCode.MISSING_REPLIES).startswith("missing replies")
    assert proto.describe_error(proto.ErrorCode.BUS_ERROR).startswith("bus error")
    assert proto.describe_error(0x42) == "unknown error code 0x42"
    assert proto.describe_state(8) == "operation enabled"


# ---- clocks --------------------------------------------------------------------------------

def test_simulated_clock_runs_hooks_before_time_moves():
    clock, seen = SimulatedClock(start=1.0), []
    clock.add_hook(lambda: seen.append(clock.now()))
    clock.sleep_until(1.5)
    clock.advance(0.25)
    clock.sleep_until(0.0)  # in the past: time does not go back
    assert seen == [1.0, 1.5, 1.75] and clock.now() == 1.75


def test_ticker_keeps_absolute_deadlines_after_a_stall():
    clock = SimulatedClock()
    ticker = Ticker(clock, T)
    assert ticker.wait() == 0.0 and clock.now() == pytest.approx(T)
    clock.advance(2.5 * T)  # the loop stalled for 2.5 periods
    late = [ticker.wait() for _ in range(4)]
    assert late == pytest.approx([1.5 * T, 0.5 * T, 0.0, 0.0])
    assert clock.now() == pytest.approx(5 * T)  # deadlines t0 + k T, not shifted


def test_real_clock_never_wakes_early():
    clock = RealClock()
    deadline = clock.now() + 0.002
    clock.sleep_until(deadline)
    assert clock.now() >= deadline


# ---- start-up ------------------------------------------------------------------------------

def test_start_reaches_operation_enabled_through_the_state_machine(make_rig):
    rig = make_rig()
    feedback = rig.start()
    assert feedback.main_state == proto.MainState.OPERATION_ENABLED
    assert proto.StatusWord.OPERATION_ENABLED in feedback.status_word
    assert feedback.actual_position == pytest.approx(rig.emulator.slider_position, abs=1e-7)
    assert rig.driver.acknowledged_error is None
    frames = rig.recorded_frames()
    assert (frames[0].arbitration_id, bytes(frames[0].data)) == (0x000, bytes([1, 63]))
    states = [proto.decode_frame(f)[1]["MainState"] for f in frames if f.arbitration_id == 0x1BF]
    assert states[-3:] == [2, 6, 8]  # one transition per SYNC


def test_start_acknowledges_a_pending_error_on_a_rising_edge(make_rig):
    rig = make_rig()
    rig.emulator.inject_error(proto.ErrorCode.MASTER_TOO_SLOW)
    assert rig.start().main_state == 8
    assert rig.driver.acknowledged_error == 0x85
    words = [int(proto.decode_frame(f)[1]["ControlWord"]) for f in rig.recorded_frames()
             if f.arbitration_id == 0x23F]
    first_ack = next(i for i, w in enumerate(words) if w & proto.ControlWord.ERROR_ACKNOWLEDGE)
    assert first_ack > 0 and not words[first_ack - 1] & proto.ControlWord.ERROR_ACKNOWLEDGE


def test_start_without_a_drive_reports_missing_replies(make_rig):
    rig = make_rig(driver_options={"node_id": 12})  # the emulated drive is node 63
    with pytest.raises(DriveFault) as caught:
        rig.driver.start()
    assert caught.value.code == proto.ErrorCode.MISSING_REPLIES
    assert "node 12" in str(caught.value)


def test_stream_refuses_use_out_of_order_and_bad_positions(make_rig):
    rig = make_rig(driver_options={"position_limits": (0.0, 0.3)})
    with pytest.raises(ProtocolError, match="start"):
        rig.driver.stream(0.1)
    rig.start()
    with pytest.raises(ValueError, match="finite"):
        rig.driver.stream(math.nan)
    with pytest.raises(ValueError, match="outside the position limits"):
        rig.driver.stream(0.31)


# ---- streaming -----------------------------------------------------------------------------

def test_limited_aprbs_run_follows_the_closed_loop_response(make_rig):
    """No stream error, and the slider follows r(t) through X/R = (3ws^2+3w^2s+w^3)/(s+w)^3.

    r(t) is built from the documented stream behaviour (setpoint j of the stream starting at tau_0
    is reached at tau_0 + (1.5 + j) T, linear in between); the response is computed by scipy's
    lsim, an independent path from the emulator's Runge-Kutta loop.
    """
    rig = make_rig()
    rig.start()
    x0 = rig.emulator.slider_position
    commands = limited_aprbs(np.random.default_rng(4), 750, start=x0, sigma=0.005)
    rig.samples.clear()
    echoes = []
    for k, position in enumerate(commands):
        rig.cycle(position)
        if k == 0:
            tau0 = rig.clock.now()
        feedback = rig.driver.feedback()
        echoes.append((feedback.command_count_echo, (rig.driver.command_count - 1) % 16))
    rig.ticker.wait()
    final = rig.driver.check()
    assert final.main_state == 8 and rig.emulator.stream_period == pytest.approx(T)
    assert all(echo == expected for echo, expected in echoes[1:])  # the count nibble echoes
    assert rig.emulator.saturated_time == 0.0, "test premise: the loop stays linear"
    quantised = np.round(commands / proto.POSITION_RESOLUTION) * proto.POSITION_RESOLUTION
    omega = 2 * np.pi * rig.emulator.parameters.position_loop_bandwidth_hz
    loop = signal.lti([3 * omega, 3 * omega**2, omega**3], [1, 3 * omega, 3 * omega**2, omega**3])
    grid = tau0 + np.arange(0.0, len(commands) * T + 1e-9, T / 8)
    reference = np.interp(grid, tau0 + (1.5 + np.arange(len(commands))) * T, quantised - x0,
                          left=0.0)
    _, expected, _ = signal.lsim(loop, reference, grid - tau0)
    times, positions = np.array(rig.samples)[:, 0], np.array(rig.samples)[:, 1]
    inside = times <= grid[-1]
    assert np.ptp(positions) > 0.02  # the run moved the slider by centimetres
    deviation = positions[inside] - x0 - np.interp(times[inside], grid, expected)
    assert np.max(np.abs(deviation)) < 1e-8  # m; Runge-Kutta at w h = 0.03 is far below


def test_commands_within_the_limiter_never_trip_the_drive(make_rig):
    """Triangles at the limiter's full rate (1.25 m/s) with the worst reversal timings."""
    rig = make_rig()
    rig.start()
    x0, worst = rig.emulator.slider_position, 0.0
    for half_period in (1, 2, 3, 5, 8, 13, 30):
        steps = np.r_[np.full(half_period, STEP_LIMIT), np.full(half_period, -STEP_LIMIT)]
        for position in x0 + np.cumsum(np.tile(steps, max(2, 60 // half_period))):
            rig.cycle(position)
            worst = max(worst, abs(rig.emulator.demand_position - rig.emulator.slider_position))
    rig.ticker.wait()
    assert rig.driver.check().main_state == 8
    assert 0.001 < worst < rig.emulator.parameters.following_error_limit


def test_a_step_beyond_the_limiter_trips_following_error_and_restarts(make_rig):
    rig = make_rig()
    rig.start()
    x0 = rig.emulator.slider_position
    with pytest.raises(DriveFault) as caught:
        for k in range(50):
            rig.cycle(x0 + (0.05 if k >= 5 else 0.0))
    fault = caught.value
    assert fault.code == 0x0B and fault.meaning == "following error: position lag always too big"
    assert fault.feedback is not None and fault.feedback.main_state in (4, 14)
    with pytest.raises(DriveFault):  # the fault is sticky
        rig.driver.stream(x0)
    rig.driver.disable()  # safe after a fault: waits until the drive is off
    assert rig.emulator.main_state == proto.MainState.ERROR
    assert rig.emulator.error_code == 0x0B and rig.emulator.slider_velocity == 0.0
    assert rig.start().main_state == 8
    assert rig.driver.acknowledged_error == 0x0B
    here = rig.emulator.slider_position
    for _ in range(10):
        rig.cycle(here)
    rig.ticker.wait()
    assert rig.driver.check().main_state == 8


def stream_at(rig, intervals, *, skip=()):
    """Stream the current position with the given intervals; cycles in `skip` send SYNC only."""
    x = rig.emulator.slider_position
    rig.driver.stream(x)
    for k, interval in enumerate(intervals):
        rig.clock.advance(interval)
        rig.driver.check()
        if k in skip:
            rig.master_bus.send(proto.sync_frame())
        else:
            rig.driver.stream(x)
    rig.clock.advance(T)
    rig.driver.check()


@pytest.mark.parametrize("intervals, skip, code", [
    ([0.001] * 5, (), 0x84),
    ([0.008] * 5, (), 0x85),
    ([T] * 10, (5, 6), 0x83),
    ([T] * 3 + [0.003] * 30, (), 0x82),
], ids=["master-too-fast", "master-too-slow", "missing-commands", "buffer-overflow"])
def test_stream_timing_errors_raise_their_codes(make_rig, intervals, skip, code):
    rig = make_rig()
    rig.start()
    with pytest.raises(DriveFault) as caught:
        stream_at(rig, intervals, skip=skip)
    assert caught.value.code == code
    assert caught.value.meaning == proto.describe_error(code)
    assert rig.emulator.error_code == code or rig.emulator.main_state == 14


def test_missing_replies_are_detected_after_reply_timeout_cycles(make_rig):
    rig = make_rig(driver_options={"reply_timeout_cycles": 3})
    rig.start()
    x = rig.emulator.slider_position
    for _ in range(5):
        rig.cycle(x)
    rig.ticker.wait()
    rig.driver.check()  # every SYNC so far is answered
    rig.emulator.silent = True
    unanswered_syncs = 0
    with pytest.raises(DriveFault) as caught:
        for _ in range(10):
            rig.cycle(x)  # raises in check() before sending another SYNC
            unanswered_syncs += 1
    assert caught.value.code == proto.ErrorCode.MISSING_REPLIES
    assert "missing replies" in str(caught.value)
    assert unanswered_syncs == 3


def test_motion_command_outside_operation_faults_with_0x86(make_rig):
    rig = make_rig()
    rig.start()
    rig.driver.disable()
    assert rig.emulator.main_state == proto.MainState.READY_TO_SWITCH_ON
    rig.master_bus.send(proto.setpoint_frame(0x3E, master_id=3, sub_id=0,
                                             count=(rig.driver.command_count + 1) % 16,
                                             position=0.1))
    rig.master_bus.send(proto.sync_frame())
    rig.clock.advance(T)
    with pytest.raises(DriveFault) as caught:
        rig.driver.check()
    assert caught.value.code == 0x86 and rig.emulator.main_state == 4
    assert "wrong state" in caught.value.meaning


def test_bus_errors_surface_as_bus_fault(make_rig):
    rig = make_rig()
    rig.start()
    rig.master_bus.shutdown()
    with pytest.raises(BusFault) as caught:
        rig.driver.stream(rig.emulator.slider_position)
    assert caught.value.code == proto.ErrorCode.BUS_ERROR
    assert isinstance(caught.value, DriveFault) and isinstance(caught.value, RigError)
    assert "closed bus" in str(caught.value)
    with pytest.raises(BusFault):
        rig.driver.check()


class FailingReceiveBus(can.BusABC):
    """A bus whose receive path reports an interface error."""

    def __init__(self):
        super().__init__(channel="failing")

    def send(self, msg, timeout=None):
        pass

    def _recv_internal(self, timeout):
        raise can.CanOperationError("controller is bus-off")


def test_receive_errors_surface_as_bus_fault():
    bus = FailingReceiveBus()
    driver = LinearMotorDriver(bus, clock=SimulatedClock())
    with pytest.raises(BusFault, match="bus-off"):
        driver.check()
    bus.shutdown()
    with pytest.raises(BusFault, match="cannot open CAN bus"):
        open_bus("no-such-interface", "x")


def test_a_bus_analyser_decodes_a_recorded_run_with_the_dbc(make_rig, tmp_path):
    rig = make_rig()
    rig.start()
    x0 = rig.emulator.slider_position
    for k in range(20):
        rig.cycle(x0 + 0.0004 * k)
    rig.ticker.wait()
    log = tmp_path / "run.log"  # candump format
    with can.Logger(str(log)) as writer:
        for frame in rig.recorded_frames():
            writer.on_message_received(frame)
    db = cantools.database.load_file(str(proto.DBC_PATH))
    decoded = [(frame.arbitration_id, db.decode_message(frame.arbitration_id, frame.data))
               for frame in can.LogReader(str(log))]
    states = [values["MainState"] for ident, values in decoded if ident == 0x1BF]
    targets = [values["TargetPosition"] for ident, values in decoded
               if ident == 0x23F and values["MotionCommandMasterId"] == 3]
    assert str(states[-1]) == "operation enabled"  # a named value of the DBC
    assert targets == pytest.approx(x0 + 0.0004 * np.arange(20), abs=1e-7)


def test_serve_answers_in_real_time(request):
    """The real-time emulator thread takes a driver through start-up and switch-off."""
    channel = f"serve-{request.node.name}"
    master, drive = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    clock, stop = RealClock(), threading.Event()
    emulator = DriveEmulator(drive, clock=clock)
    thread = threading.Thread(target=emulator.serve, args=(stop,), daemon=True)
    thread.start()
    try:
        driver = LinearMotorDriver(master, clock=clock, reply_timeout_cycles=100)
        assert driver.start().main_state == 8
        assert driver.disable().main_state == 2
    finally:
        stop.set()
        thread.join(timeout=5)
        master.shutdown()
        drive.shutdown()
    assert not thread.is_alive()
