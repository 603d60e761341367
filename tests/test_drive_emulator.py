"""The drive emulator on its own, driven by raw frames (not by the driver) on the virtual bus.

The closed-loop checks compare against closed forms of the documented loop: with all three poles
at -w, the tracking error is E(s) = s^3/(s+w)^3 R(s) and a load F_L moves the slider by
X(s) = F_L(s)/m / (s+w)^3 * s.
"""
import math

import can
import numpy as np
import pytest

from panto.rig import can_protocol as proto
from panto.rig.clock import SimulatedClock
from panto.rig.drive_emulator import DriveEmulator, DriveParameters

T = 0.004
RUNNING, READY, OFF = 0x003F, 0x003E, 0x0000


class Master:
    """A bare CAN master: sends RxPDO1 + SYNC, steps the emulator, collects the replies."""

    def __init__(self, channel, **emulator_options):
        self.clock = SimulatedClock()
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.drive_bus = can.Bus(interface="virtual", channel=channel)
        self.samples = []
        self.emulator = DriveEmulator(self.drive_bus, clock=self.clock,
                                      listener=lambda t, x, v: self.samples.append((t, x, v)),
                                      **emulator_options)
        self.count = 0

    def nmt(self, command):
        self.bus.send(proto.nmt_frame(command, 63))
        self.emulator.process_pending()

    def cycle(self, control_word=RUNNING, *, position=None, stop=False, advance=True):
        """Advance one period, send RxPDO1 (a new command if position/stop) and SYNC."""
        if advance:
            self.clock.advance(T)
        master = sub = 0
        if position is not None or stop:
            self.count, master = (self.count + 1) % 16, 3
            sub = 0xF if stop else 0
        self.bus.send(proto.setpoint_frame(control_word, master_id=master, sub_id=sub,
                                           count=self.count, position=position or 0.0))
        self.bus.send(proto.sync_frame())
        self.emulator.process_pending()
        return self.replies()

    def replies(self):
        """Merged signals of the TxPDOs that arrived (None if there were none)."""
        merged = {}
        while (frame := self.bus.recv(timeout=0)) is not None:
            merged.update(proto.decode_frame(frame)[1])
        return merged or None

    def enable(self):
        self.nmt(proto.NmtCommand.START_REMOTE_NODE)
        states = [self.cycle(READY)["MainState"]] + [self.cycle(RUNNING)["MainState"]
                                                      for _ in range(2)]
        assert states == [2, 6, 8]

    def close(self):
        self.bus.shutdown()
        self.drive_bus.shutdown()


@pytest.fixture
def make_master(request):
    masters = []

    def factory(**options):
        master = Master(f"{request.node.name}-{len(masters)}", **options)
        masters.append(master)
        return master

    yield factory
    for master in masters:
        master.close()


def ramp_error(t, omega):
    """Tracking error per unit ramp slope: L^-1[s/(s+w)^3] = (t - w t^2/2) e^(-w t), t >= 0."""
    t = np.maximum(t, 0.0)
    return (t - 0.5 * omega * t**2) * np.exp(-omega * t)


def test_nmt_and_the_control_word_state_machine(make_master):
    master = make_master()
    assert master.cycle(RUNNING) is None  # pre-operational: no PDOs
    master.nmt(proto.NmtCommand.START_REMOTE_NODE)
    assert master.cycle(OFF)["MainState"] == 2
    assert [master.cycle(RUNNING)["MainState"] for _ in range(3)] == [6, 8, 8]
    assert master.cycle(0x0037)["MainState"] == 6  # enable operation off
    assert master.cycle(RUNNING)["MainState"] == 8
    quick_stop = master.cycle(RUNNING & ~int(proto.ControlWord.NOT_QUICK_STOP))
    assert quick_stop["MainState"] == 14 and quick_stop["LoggedErrorCode"] == 0
    assert master.cycle(READY)["MainState"] == 2  # quick stop released at standstill
    assert master.cycle(RUNNING)["MainState"] == 6
    master.nmt(proto.NmtCommand.STOP_REMOTE_NODE)
    assert master.cycle(RUNNING) is None


def test_errors_are_acknowledged_only_on_a_rising_edge_of_bit_7(make_master):
    master = make_master()
    master.nmt(proto.NmtCommand.START_REMOTE_NODE)
    master.cycle(0x0080)
    master.emulator.inject_error(0x84)
    held = master.cycle(0x0080)  # bit 7 already high: no edge
    assert (held["MainState"], held["StateLowByte"], held["LoggedErrorCode"]) == (4, 0x84, 0x84)
    assert proto.StatusWord.ERROR in proto.StatusWord(int(held["StatusWord"]))
    assert master.cycle(OFF)["MainState"] == 4
    cleared = master.cycle(0x0080)
    assert (cleared["MainState"], cleared["LoggedErrorCode"]) == (2, 0)


@pytest.mark.parametrize("period", [0.004, 0.003])
def test_setpoints_are_delayed_by_one_and_a_half_periods_and_interpolated(make_master, period):
    """At SYNC k the demand is halfway between setpoints k-2 and k-1 (delay 1.5 T, linear)."""
    master = make_master()
    master.enable()
    x0 = master.emulator.slider_position
    commands = x0 + np.r_[0.0, np.random.default_rng(7).uniform(-0.001, 0.001, 40)]
    demands = []
    for position in commands:
        master.clock.advance(period)
        demands.append(master.cycle(position=position, advance=False)["DemandPosition"])
    assert master.emulator.stream_period == pytest.approx(period)
    expected = 0.5 * (commands[:-2] + commands[1:-1])
    assert np.array(demands[2:]) == pytest.approx(expected, abs=1.5e-7)


@pytest.mark.parametrize("correction, expected_code", [(0.0, 0x82), (0.2, None)])
def test_a_mismeasured_period_overflows_unless_the_time_base_is_corrected(
        make_master, correction, expected_code):
    """The second command comes 0.5 ms late, later ones on time: the drive consumes at 4.5 ms
    per setpoint while they arrive every 4 ms, so its buffer fills (g = 0) unless the schedule is
    pulled towards the arrivals (g > 0: the delay settles and nothing overflows)."""
    master = make_master(timebase_correction=correction)
    master.enable()
    x0 = master.emulator.slider_position
    master.cycle(position=x0)
    master.clock.advance(0.0005)
    states = [master.cycle(position=x0)["MainState"]]
    states += [master.cycle(position=x0)["MainState"] for _ in range(200)]
    assert master.emulator.error_code == (expected_code or 0)
    assert (states[-1] == 8) == (expected_code is None)


def test_a_small_step_follows_the_closed_form_response(make_master):
    """x = r - e with e = (H/T) [g(t - s_a) - g(t - s_b)], g the unit-ramp error."""
    master = make_master()
    master.enable()
    x0, height, jump = master.emulator.slider_position, 0.002, 5
    master.samples.clear()
    for k in range(40):
        master.cycle(position=x0 + (height if k >= jump else 0.0))
        if k == 0:
            tau0 = master.clock.now()
    omega = 2 * math.pi * master.emulator.parameters.position_loop_bandwidth_hz
    start, end = tau0 + (1.5 + jump - 1) * T, tau0 + (1.5 + jump) * T
    t, x = np.array(master.samples)[:, 0], np.array(master.samples)[:, 1]
    reference = x0 + height * np.clip((t - start) / T, 0.0, 1.0)
    expected = reference - height / T * (ramp_error(t - start, omega) - ramp_error(t - end, omega))
    assert np.max(x) - x0 > 1.05 * height  # the loop overshoots (zeros of the PID)
    assert np.max(np.abs(x - expected)) < 1e-4 * height
    assert master.emulator.saturated_time == 0.0


def test_a_load_step_is_rejected_as_the_closed_form_predicts(make_master):
    """A load F from t_on moves the slider by F/m * tau^2/2 * exp(-w tau), then not at all."""
    force, t_on = 100.0, 0.02
    box = {}
    master = make_master(load_force=lambda: force if box["emulator"].time >= t_on - 1e-12 else 0.0)
    box["emulator"] = master.emulator
    master.enable()
    x0 = master.emulator.slider_position
    master.samples.clear()
    for _ in range(50):
        replies = master.cycle(position=x0)
    p = master.emulator.parameters
    omega = 2 * math.pi * p.position_loop_bandwidth_hz
    t, x = np.array(master.samples)[:, 0], np.array(master.samples)[:, 1]
    tau = np.maximum(t - t_on, 0.0)
    expected = x0 + force / p.moving_mass * 0.5 * tau**2 * np.exp(-omega * tau)
    peak = force / p.moving_mass * 2 / omega**2 * math.exp(-2)
    assert np.max(x - x0) == pytest.approx(peak, rel=0.01)
    assert np.max(np.abs(x - expected)) < 1e-3 * peak
    # force balance at rest: the motor holds the load, current = -F / k_F
    assert replies["DemandCurrent"] == pytest.approx(-force / p.force_constant, abs=2e-3)


def test_following_error_quick_stops_then_errors_with_0x0B(make_master):
    master = make_master(quick_stop_deceleration=40.0)
    master.enable()
    x0 = master.emulator.slider_position
    for _ in range(3):
        master.cycle(position=x0)
    replies = [master.cycle(position=x0 + 0.05) for _ in range(40)]
    states = [r["MainState"] for r in replies]
    first_stop = states.index(14)
    assert set(states[:first_stop]) == {8} and 4 in states
    stopping = replies[first_stop]
    assert stopping["LoggedErrorCode"] == 0x0B
    assert proto.StatusWord.ERROR in proto.StatusWord(int(stopping["StatusWord"]))
    error = replies[states.index(4)]
    assert (error["StateLowByte"], error["LoggedErrorCode"]) == (0x0B, 0x0B)
    assert set(states[states.index(4):]) == {4}  # later commands do not change the error
    # while stopping, the velocity falls by a * dt between listener samples
    t, x, v = np.array(master.samples).T
    braking = (np.abs(v[1:]) > 0) & (np.abs(v[:-1]) > 0) & (np.abs(np.diff(v)) < 0.1)
    braking &= t[1:] > tau_fault(master, t, x, v)
    assert braking.sum() >= 3
    assert np.abs(np.diff(v))[braking] == pytest.approx(40.0 * 0.002, rel=1e-9)
    assert master.emulator.slider_velocity == 0.0
    assert master.emulator.error_code == 0x0B


def tau_fault(master, t, x, v):
    """Time of the largest speed: the quick stop begins right after it."""
    return t[np.argmax(np.abs(v))]


def test_position_lag_pre_warning_without_a_fault(make_master):
    master = make_master()
    master.enable()
    x0 = master.emulator.slider_position
    replies = [master.cycle(position=x0 + (0.02 if k >= 2 else 0.0)) for k in range(40)]
    warned = [bool(r["WarnWord"] & proto.WarnWord.POSITION_LAG) for r in replies]
    lags = [abs(r["DemandPosition"] - r["ActualPosition"]) for r in replies]
    assert any(warned) and not warned[-1]
    assert all(state == 8 for state in (r["MainState"] for r in replies))
    limit = master.emulator.parameters.following_error_warning
    assert all(w for lag, w in zip(lags, warned) if lag > limit)  # latched between SYNCs
    for r, w in zip(replies, warned):
        assert (proto.StatusWord.WARNING in proto.StatusWord(int(r["StatusWord"]))) == w


def test_stop_streaming_holds_and_the_stream_restarts(make_master):
    master = make_master()
    master.enable()
    x0 = master.emulator.slider_position
    for k in range(10):
        master.cycle(position=x0 + 0.0005 * k)
    master.cycle(stop=True)
    held = [master.cycle()["DemandPosition"] for _ in range(30)]
    assert max(held) - min(held) < 1e-7 and master.emulator.stream_period is None
    assert master.emulator.slider_position == pytest.approx(held[-1], abs=1e-6)
    master.clock.advance(1.0)  # a pause does not matter once the stream has stopped
    for _ in range(5):
        assert master.cycle(position=held[-1])["MainState"] == 8


def test_demand_is_clipped_to_the_travel(make_master):
    master = make_master(travel=(0.0, 0.1), initial_position=0.099)
    master.enable()
    for k in range(30):
        replies = master.cycle(position=min(0.099 + 0.0005 * k, 0.11))
    assert replies["DemandPosition"] == pytest.approx(0.1)
    assert master.emulator.slider_position <= 0.1 + 1e-6


def test_listener_is_called_every_two_milliseconds(make_master):
    master = make_master()
    master.enable()
    master.samples.clear()
    for _ in range(10):
        master.cycle()
    t = np.array(master.samples)[:, 0]
    assert len(t) == 20 and np.diff(t) == pytest.approx(0.002)
    assert t[-1] == pytest.approx(master.clock.now())


def test_nmt_reset_node_clears_an_error(make_master):
    master = make_master()
    master.enable()
    master.emulator.inject_error(0x83)
    assert master.cycle()["MainState"] == 4
    master.nmt(proto.NmtCommand.RESET_NODE)
    assert master.cycle() is None
    master.nmt(proto.NmtCommand.START_REMOTE_NODE)
    assert master.cycle(OFF)["MainState"] == 2


@pytest.mark.parametrize("field, value, message", [
    ("moving_mass", 0.0, "moving_mass"),
    ("travel", (0.3, 0.1), "travel"),
    ("stream_delay_periods", 1.0, "stream_delay_periods"),
    ("listener_period", 0.0021, "multiple of internal_step"),
    ("timebase_correction", 2.0, "timebase_correction"),
])
def test_bad_parameters_are_refused_by_name(field, value, message):
    with pytest.raises(ValueError, match=message):
        DriveParameters(**{field: value})


def test_bad_emulator_options_are_refused(request):
    bus = can.Bus(interface="virtual", channel=request.node.name)
    try:
        with pytest.raises(TypeError, match="bandwith"):
            DriveEmulator(bus, clock=SimulatedClock(), bandwith=3)
        with pytest.raises(ValueError, match="outside the travel"):
            DriveEmulator(bus, clock=SimulatedClock(), initial_position=2.0)
    finally:
        bus.shutdown()
