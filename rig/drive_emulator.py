"""An emulated linear-motor drive that answers on the CAN bus like the rig's real drive.

The emulator reads the master's frames (NMT, RxPDO1, SYNC; layout in ``linear_motor.dbc``) and
answers every SYNC with TxPDO1..3, like the LinMot-type drive of the thesis' rig (Kalteis,
section 3.1; protocol facts in :mod:`panto.rig.can_protocol`):

* NMT: PDOs are handled only after "start remote node".
* Control-word state machine: 2 ready to switch on -> 6 ready to operate -> 8 operation enabled
  (one transition per SYNC); 14 quick stop; 4 error, left by a rising edge of control-word bit 7.
* Position stream (030x): the period :math:`T` is measured from the first two commands; every
  setpoint :math:`c_j` is scheduled :math:`1.5\\,T` after its SYNC on the drive's own time base,
  :math:`s_j = s_0 + j\\,T` with :math:`s_0 = \\tau_0 + 1.5\\,T`, and the demand position is the
  linear interpolation between the scheduled setpoints. Until :math:`T` is known the demand holds;
  it then moves from the hold position at :math:`\\tau_1` to :math:`c_0` at :math:`s_0`, half a
  period later, so a stream should start at the current position. Stream errors: command
  intervals outside 2-5 ms (0x84 too fast / 0x85 too slow), the next setpoint missing when the
  interpolation needs it (0x83 underflow), more than ``stream_buffer_size`` setpoints waiting
  (0x82 overflow). A motion command outside state 8 raises 0x86. 03Fx stops the stream (the
  demand holds where it is).
* Following error: when :math:`|r - x|` exceeds 30 mm the drive quick-stops (state 14, the slider
  decelerates at ``quick_stop_deceleration``) and then goes to state 4 with error 0x0B. The
  position-lag pre-warning (warn word bit 4) reports whether :math:`|r - x|` exceeded
  ``following_error_warning`` at any time since the previous SYNC.

Position loop (state 8)
    The slider of mass :math:`m` carries the motor force :math:`F_m` and the load force
    :math:`F_L` from the plant (the force the pantograph pushes on the slider, positive along +x):
    :math:`m\\ddot x = F_m + F_L`. The drive's controller is a PID on the error
    :math:`e = r - x` (the D term acts on :math:`\\dot r - \\dot x`, i.e. includes velocity
    feed-forward), with gains from placing all three closed-loop poles at :math:`-\\omega`,
    :math:`\\omega = 2\\pi f_{bw}` (``position_loop_bandwidth_hz``):

    .. math::
        F_m = \\mathrm{sat}_{F_{max}}\\big(m\\,[\\omega^3 \\textstyle\\int e\\,dt + 3\\omega^2 e
        + 3\\omega\\,\\dot e]\\big),

    so that, without saturation,

    .. math::
        X(s) = \\frac{3\\omega s^2 + 3\\omega^2 s + \\omega^3}{(s+\\omega)^3} R(s)
        + \\frac{s}{(s+\\omega)^3}\\frac{F_L(s)}{m},\\qquad
        R(s) - X(s) = \\frac{s^3}{(s+\\omega)^3}R(s).

    Tracking errors of components well below :math:`f_{bw}` shrink like :math:`(f/f_{bw})^3`; a
    constant load is rejected completely (integral action; the integrator is preloaded with the
    current load when operation is enabled, as a drive releasing its brake does). The integral is
    frozen while the force saturates (anti-windup). Default :math:`f_{bw}` = 20 Hz, m = 2 kg,
    :math:`F_{max}` = 1000 N. The loop is integrated with classical Runge-Kutta at
    ``internal_step`` (0.25 ms); the piecewise-linear setpoint is exact within each step.

Outside states 8 and 14 the slider is held still (power stage off, brake engaged); when operation
is left while the slider moves, it first decelerates at ``quick_stop_deceleration``.

Running it: :meth:`DriveEmulator.process_pending` handles all frames waiting on the bus at the
clock's current time and advances the slider to that time (tests and the lock-step virtual test bed
call it once per cycle, or register it with :meth:`panto.rig.clock.SimulatedClock.add_hook`);
:meth:`DriveEmulator.serve` does the same in a real-time thread. The slider is advanced in internal
steps; ``listener(time, position, velocity)`` is called every ``listener_period`` (2 ms, so a plant
can be stepped at 500 Hz) and ``load_force()`` is read every internal step.
"""
from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import can

from panto.rig.can_protocol import (
    DEFAULT_NODE_ID,
    STREAM_MASTER_ID,
    ControlWord,
    ErrorCode,
    FrameIds,
    MainState,
    NmtCommand,
    StatusWord,
    StreamCommand,
    WarnWord,
    decode_frame,
    encode_frame,
    load_database,
)
from panto.rig.clock import Clock

Listener = Callable[[float, float, float], object]
_OPERATION, _ERROR, _QUICK_STOP = (MainState.OPERATION_ENABLED, MainState.ERROR,
                                   MainState.QUICK_STOP)
_HOMED, _OPERATION_ENABLED_BIT, _ERROR_BIT, _WARNING_BIT, _IN_TARGET_BIT, _MOTION_ACTIVE_BIT = (
    int(StatusWord.HOMED), int(StatusWord.OPERATION_ENABLED), int(StatusWord.ERROR),
    int(StatusWord.WARNING), int(StatusWord.IN_TARGET_POSITION), int(StatusWord.MOTION_ACTIVE))
_POSITION_LAG_BIT = int(WarnWord.POSITION_LAG)


@dataclass(frozen=True)
class DriveParameters:
    """Parameters of the emulated drive and slider (SI units).

    Attributes
    ----------
    moving_mass : float
        Slider mass m [kg].
    position_loop_bandwidth_hz : float
        f_bw: the closed loop's triple pole sits at -2 pi f_bw [Hz].
    peak_force : float
        Saturation of the motor force [N].
    force_constant : float
        Motor force per ampere, for the reported demand current [N/A].
    following_error_limit, following_error_warning : float
        |r - x| that trips error 0x0B (thesis: 30 mm) / sets the pre-warning [m].
    travel : (float, float)
        Slider travel (min, max) [m]; demand positions are clipped to it.
    quick_stop_deceleration : float
        Braking deceleration in quick stop [m/s^2].
    stream_period_range : (float, float)
        Allowed interval between stream commands (min, max) [s].
    stream_delay_periods : float
        Setpoint delay in stream periods (> 1; the drive uses 1.5).
    stream_buffer_size : int
        Setpoints that may wait ahead of the interpolation before 0x82.
    timebase_correction : float
        g in [0, 1]. 0 keeps the drive's own time base, s_j = s_{j-1} + T with T measured from
        the first two commands (the documented drive). g > 0 updates T <- T + g (interval - T)
        and pulls each schedule point towards arrival + delay by the fraction g, so that a
        real-time emulator tolerates a jittery master (whose first interval may be off).
    internal_step, listener_period : float
        Integration step and listener sample period [s]; the first must divide the second.
    in_target_window : float
        |r - x| below which the status bit "in target position" is set [m].
    """

    moving_mass: float = 2.0
    position_loop_bandwidth_hz: float = 20.0
    peak_force: float = 1000.0
    force_constant: float = 20.0
    following_error_limit: float = 0.030
    following_error_warning: float = 0.015
    travel: tuple[float, float] = (-0.15, 0.15)
    quick_stop_deceleration: float = 50.0
    stream_period_range: tuple[float, float] = (0.002, 0.005)
    stream_delay_periods: float = 1.5
    stream_buffer_size: int = 4
    timebase_correction: float = 0.0
    internal_step: float = 0.00025
    listener_period: float = 0.002
    in_target_window: float = 1e-4

    def __post_init__(self) -> None:
        positive = ("moving_mass", "position_loop_bandwidth_hz", "peak_force", "force_constant",
                    "following_error_limit", "following_error_warning",
                    "quick_stop_deceleration", "internal_step", "listener_period",
                    "in_target_window")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"DriveParameters.{name} must be a finite number > 0, "
                                 f"got {value!r}")
        for name in ("travel", "stream_period_range"):
            low, high = getattr(self, name)
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise ValueError(f"DriveParameters.{name} must be (low, high) with low < high, "
                                 f"got {getattr(self, name)!r}")
        if not self.stream_delay_periods > 1.0:
            raise ValueError("DriveParameters.stream_delay_periods must be > 1, "
                             f"got {self.stream_delay_periods!r}")
        if not (isinstance(self.stream_buffer_size, int) and self.stream_buffer_size >= 2):
            raise ValueError("DriveParameters.stream_buffer_size must be an integer >= 2, "
                             f"got {self.stream_buffer_size!r}")
        if not 0.0 <= self.timebase_correction <= 1.0:
            raise ValueError("DriveParameters.timebase_correction must be in [0, 1], "
                             f"got {self.timebase_correction!r}")
        ratio = self.listener_period / self.internal_step
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(f"DriveParameters.listener_period ({self.listener_period}) must be "
                             f"a multiple of internal_step ({self.internal_step})")

    @property
    def loop_gains(self) -> tuple[float, float, float]:
        """(k_i, k_p, k_d) = (w^3, 3 w^2, 3 w) [1/s^3, 1/s^2, 1/s], w = 2 pi f_bw."""
        omega = 2.0 * math.pi * self.position_loop_bandwidth_hz
        return omega**3, 3.0 * omega**2, 3.0 * omega


class SetpointStream:
    """Stream setpoints on the drive's time base, linearly interpolated (see the module notes).

    Parameters
    ----------
    hold
        Demand position before the stream [m]; the interpolation starts from it.
    parameters
        Stream timing parameters.
    """

    def __init__(self, hold: float, parameters: DriveParameters) -> None:
        self._hold = hold
        self._p = parameters
        self._first: tuple[float, float] | None = None
        self._last_arrival: float | None = None
        self.period: float | None = None
        self._times: list[float] = []
        self._values: list[float] = []
        self._index = 0

    @property
    def available_until(self) -> float:
        """Schedule time of the newest setpoint (inf before the period is known: holding)."""
        return self._times[-1] if self._times else math.inf

    def add(self, arrival: float, value: float) -> ErrorCode | None:
        """Take a setpoint that became effective at `arrival`; return a stream error or None."""
        p = self._p
        if self._last_arrival is not None:
            interval = arrival - self._last_arrival
            if interval < p.stream_period_range[0]:
                return ErrorCode.MASTER_TOO_FAST
            if interval > p.stream_period_range[1]:
                return ErrorCode.MASTER_TOO_SLOW
        self._last_arrival = arrival
        delay = p.stream_delay_periods
        if self._first is None:
            self._first = (arrival, value)
            return None
        if self.period is None:
            self.period = arrival - self._first[0]
            self._times = [arrival, self._first[0] + delay * self.period]
            self._values = [self._hold, self._first[1]]
        else:  # g > 0: the period estimate follows the mean command interval
            self.period += p.timebase_correction * (interval - self.period)
        nominal = self._times[-1] + self.period
        scheduled = nominal + p.timebase_correction * (arrival + delay * self.period - nominal)
        self._times.append(max(scheduled, self._times[-1] + 0.25 * self.period))
        self._values.append(value)
        waiting = sum(1 for t in self._times[self._index + 1:] if t > arrival)
        return ErrorCode.BUFFER_OVERFLOW if waiting > p.stream_buffer_size else None

    def segment(self, time: float) -> tuple[float, float, float]:
        """(t0, r0, slope) of the interpolation line valid at `time` (hold outside the data)."""
        times = self._times
        if not times or time <= times[0]:
            return time, self._hold if not times else self._values[0], 0.0
        while self._index + 2 < len(times) and time > times[self._index + 1]:
            self._index += 1
        if self._index > 256:  # forget consumed setpoints
            del times[: self._index], self._values[: self._index]
            self._index = 0
        k = self._index
        if time > times[-1]:
            return time, self._values[-1], 0.0
        slope = (self._values[k + 1] - self._values[k]) / (times[k + 1] - times[k])
        return times[k], self._values[k], slope


def _within(r: float, slope: float, low: float, high: float) -> tuple[float, float]:
    """The demand position and velocity clipped to the travel ``[low, high]`` (at rest there)."""
    if r < low:
        return low, 0.0
    if r > high:
        return high, 0.0
    return r, slope


def _stage(gains: tuple, r: float, v_ref: float, x: float, v: float, z: float
           ) -> tuple[float, float, float, float]:
    """One Runge-Kutta stage of the position loop: ``(x', v', z')`` at the state ``(x, v, z)``
    for the demand ``(r, v_ref)``, and the PID force demand before saturation. The force
    saturates at the peak; while it winds up against the limit the integrator is held."""
    m, f_max, k_i, k_p, k_d, load = gains
    e = r - x
    demand = m * (k_i * z + k_p * e + k_d * (v_ref - v))
    force = f_max if demand > f_max else -f_max if demand < -f_max else demand
    if force != demand and (e > 0.0) == (demand > 0.0):
        e = 0.0
    return v, (force + load) / m, e, demand


class DriveEmulator:
    """The rig's linear-motor drive, emulated on a python-can bus (see the module notes).

    Parameters
    ----------
    bus
        The emulator's own bus object (on the master's channel).
    clock
        Time source; a :class:`panto.rig.clock.SimulatedClock` for lock-step runs.
    node_id
        CANopen node id (default 63).
    parameters
        :class:`DriveParameters`; keyword `overrides` replace single fields, e.g.
        ``position_loop_bandwidth_hz=30.0, following_error_limit=0.030, travel=(0.0, 0.4)``.
    listener
        ``listener(time, slider_position, slider_velocity)``, called every ``listener_period``.
    load_force
        ``load_force() -> float``: force of the plant on the slider [N] (positive along +x),
        read every internal step.
    initial_position
        Slider position at start [m]; default mid-travel.
    """

    def __init__(self, bus: can.BusABC, *, clock: Clock, node_id: int = DEFAULT_NODE_ID,
                 parameters: DriveParameters | None = None, listener: Listener | None = None,
                 load_force: Callable[[], float] | None = None,
                 initial_position: float | None = None, **overrides: object) -> None:
        base = parameters if parameters is not None else DriveParameters()
        unknown = set(overrides) - {f.name for f in dataclasses.fields(DriveParameters)}
        if unknown:
            raise TypeError(f"unknown drive parameter(s) {sorted(unknown)}")
        self._p = dataclasses.replace(base, **overrides) if overrides else base
        self._bus, self._clock = bus, clock
        self._ids = FrameIds.for_node(node_id)
        load_database()  # parse the DBC now, not when the first frame arrives
        self._listener, self._load_force = listener, load_force
        low, high = self._p.travel
        x0 = 0.5 * (low + high) if initial_position is None else float(initial_position)
        if not low <= x0 <= high:
            raise ValueError(f"initial_position {x0} m is outside the travel {self._p.travel}")
        self._h = self._p.internal_step
        self._gains = self._p.loop_gains
        self._loop_constants = (self._p.moving_mass, self._p.peak_force, *self._p.travel,
                                *self._gains)
        self._ratio = round(self._p.listener_period / self._h)
        self._t0, self._steps = clock.now(), 0
        self._x, self._v, self._z, self._force, self._lag = x0, 0.0, 0.0, 0.0, 0.0
        self.silent = False
        """When True the drive sends no replies (a dead drive or a broken cable)."""
        self.saturated_time = 0.0
        """Time the motor force spent at its limit [s]."""
        self.malformed_frames = 0
        self.ignored_commands = 0
        self._reset_drive()

    def _reset_drive(self) -> None:
        self._operational = False
        self._state: int = MainState.READY_TO_SWITCH_ON
        self._error_code = self._logged_error = 0
        self._fault_pending: int | None = None
        self._control_word, self._last_count, self._echo = 0, 0, 0
        self._pending_setpoint: dict[str, float] | None = None
        self._stream: SetpointStream | None = None
        self._hold, self._warn, self._warned = self._x, False, False

    # ---- read-out ---------------------------------------------------------------------------
    @property
    def parameters(self) -> DriveParameters:
        """The drive parameters in use."""
        return self._p

    @property
    def time(self) -> float:
        """Time up to which the slider has been advanced [s]."""
        return self._t0 + self._steps * self._h

    @property
    def slider_position(self) -> float:
        """True slider position x [m] (unquantised; for the truth record)."""
        return self._x

    @property
    def slider_velocity(self) -> float:
        """True slider velocity [m/s]."""
        return self._v

    @property
    def demand_position(self) -> float:
        """Interpolated demand position r at :attr:`time` [m] (x outside state 8)."""
        return self._reference(self.time)[0] if self._state == _OPERATION else self._x

    @property
    def motor_force(self) -> float:
        """Motor force of the last internal step [N]."""
        return self._force

    @property
    def main_state(self) -> int:
        """Main state (:class:`panto.rig.can_protocol.MainState` values)."""
        return self._state

    @property
    def error_code(self) -> int:
        """Error code of state 4 (0 otherwise)."""
        return self._error_code

    @property
    def stream_period(self) -> float | None:
        """Stream period measured from the first two commands [s], None when not streaming."""
        return self._stream.period if self._stream is not None else None

    def inject_error(self, code: int) -> None:
        """Fault the drive with `code` now, as if it had detected that error."""
        self._fault(int(code))

    # ---- running ----------------------------------------------------------------------------
    def process_pending(self) -> int:
        """Handle every frame waiting on the bus at ``clock.now()``; return how many there were.

        The slider is then advanced to ``clock.now()`` as well.
        """
        handled = 0
        while (frame := self._bus.recv(timeout=0.0)) is not None:
            self.receive(frame)
            handled += 1
        self._advance_to(self._clock.now())
        return handled

    def serve(self, stop_event: threading.Event, *, poll_interval: float = 0.001) -> None:
        """Answer frames in real time until `stop_event` is set (run it in a thread).

        A frame takes effect at its arrival on the bus, ``now - (time.time() - timestamp)``
        (python-can stamps received frames with ``time.time()``), so a late wake-up of this
        thread does not shift the stream timing; implausible ages (< 0 or > 50 ms, e.g. hardware
        clocks with another epoch) fall back to ``now``.
        """
        while not stop_event.is_set():
            frame = self._bus.recv(timeout=poll_interval)
            now = self._clock.now()
            if frame is None:
                self._advance_to(now)
                continue
            age = time.time() - frame.timestamp
            self.receive(frame, now - age if 0.0 <= age <= 0.05 else now)

    def receive(self, frame: can.Message, time: float | None = None) -> None:
        """Handle one frame that arrived at `time` (default ``clock.now()``)."""
        now = self._clock.now() if time is None else time
        try:
            decoded = decode_frame(frame, node_id=self._ids.node_id)
        except ValueError:
            self.malformed_frames += 1
            return
        if decoded is None:
            return
        name, values = decoded
        if name == "SYNC":
            self._on_sync(now)
        elif name == "RxPDO1" and self._operational:
            self._pending_setpoint = values
        elif name == "NMT" and int(values["NmtNodeId"]) in (0, self._ids.node_id):
            self._on_nmt(int(values["NmtCommand"]))

    def _on_nmt(self, command: int) -> None:
        if command == NmtCommand.START_REMOTE_NODE:
            self._operational = True
        elif command == NmtCommand.RESET_NODE:
            self._reset_drive()
        else:
            self._operational = False

    def _on_sync(self, now: float) -> None:
        self._advance_to(now)
        if not self._operational:
            return
        setpoint, self._pending_setpoint = self._pending_setpoint, None
        control_word = int(setpoint["ControlWord"]) if setpoint else self._control_word
        self._apply_control_word(control_word)
        if setpoint is not None:
            self._apply_motion_command(setpoint, now)
        if not self.silent:
            self._send_replies(now)

    # ---- state machine ----------------------------------------------------------------------
    def _apply_control_word(self, word: int) -> None:
        previous, self._control_word = self._control_word, word
        if self._state == _ERROR:
            acknowledge = ControlWord.ERROR_ACKNOWLEDGE
            if word & acknowledge and not previous & acknowledge:
                self._error_code = self._logged_error = 0
                self._state = MainState.READY_TO_SWITCH_ON
            return
        if self._fault_pending is not None:
            return  # a fault's quick stop runs to its end
        state = self._state
        if not word & ControlWord.VOLTAGE_ENABLE or (
                not word & ControlWord.SWITCH_ON and word & ControlWord.NOT_QUICK_STOP):
            new = MainState.READY_TO_SWITCH_ON
        elif not word & ControlWord.NOT_QUICK_STOP:
            stoppable = state in (_OPERATION, _QUICK_STOP)
            new = _QUICK_STOP if stoppable else MainState.READY_TO_SWITCH_ON
        elif state == _QUICK_STOP:
            new = MainState.READY_TO_SWITCH_ON if self._v == 0.0 else _QUICK_STOP
        elif state == MainState.READY_TO_SWITCH_ON:
            new = MainState.READY_TO_OPERATE
        else:
            new = _OPERATION if word & ControlWord.ENABLE_OPERATION else MainState.READY_TO_OPERATE
        self._set_state(new)

    def _set_state(self, new: int) -> None:
        if new == self._state:
            return
        if new == _OPERATION:  # take over where the slider is, integrator holding the load
            k_i = self._p.loop_gains[0]
            self._hold, self._stream = self._x, None
            self._z = -self._current_load() / (self._p.moving_mass * k_i)
        if self._state == _OPERATION:
            self._stream, self._warn = None, False
        self._state = new

    def _apply_motion_command(self, setpoint: dict[str, float], now: float) -> None:
        count, master = int(setpoint["MotionCommandCount"]), int(setpoint["MotionCommandMasterId"])
        is_new = master != 0 and count != self._last_count
        self._last_count = count
        if not is_new or self._state == _ERROR or self._fault_pending is not None:
            return
        if self._state != _OPERATION:
            self._fault(ErrorCode.MOTION_COMMAND_WRONG_STATE)
            return
        self._echo = count
        sub = int(setpoint["MotionCommandSubId"])
        if master == STREAM_MASTER_ID and sub == StreamCommand.POSITION:
            if self._stream is None:
                self._stream = SetpointStream(self._hold, self._p)
            error = self._stream.add(now, float(setpoint["TargetPosition"]))
            if error is not None:
                self._fault(error)
        elif master == STREAM_MASTER_ID and sub == StreamCommand.STOP:
            self._hold, self._stream = self._reference(self.time)[0], None
        else:
            self.ignored_commands += 1

    def _fault(self, code: int) -> None:
        self._logged_error, self._stream, self._warn = code, None, False
        if self._state in (_OPERATION, _QUICK_STOP) and self._v != 0.0:
            self._state, self._fault_pending = _QUICK_STOP, code
        else:
            self._enter_error(code)

    def _enter_error(self, code: int) -> None:
        self._state, self._error_code, self._fault_pending, self._v = _ERROR, code, None, 0.0

    # ---- slider dynamics --------------------------------------------------------------------
    def _current_load(self) -> float:
        return float(self._load_force()) if self._load_force is not None else 0.0

    def _reference(self, time: float) -> tuple[float, float]:
        """Demand position and velocity at `time`, clipped to the travel."""
        if self._stream is None:
            t0, r0, slope = time, self._hold, 0.0
        else:
            t0, r0, slope = self._stream.segment(time)
        return self._clip(r0 + slope * (time - t0), slope)

    def _clip(self, position: float, velocity: float) -> tuple[float, float]:
        low, high = self._p.travel
        if position < low:
            return low, 0.0
        if position > high:
            return high, 0.0
        return position, velocity

    def _advance_to(self, time: float) -> None:
        target = math.floor((time - self._t0) / self._h + 1e-6)
        while self._steps < target:
            self._step()

    def _step(self) -> None:
        h = self._h
        t = self._t0 + self._steps * h  # self.time, inline: 1.5 million steps per 380 s
        if self._state == _OPERATION:
            stream = self._stream
            if stream is not None and t + h > stream.available_until + 1e-9 * h:
                self._fault(ErrorCode.BUFFER_UNDERFLOW)
        if self._state == _OPERATION:
            self._controlled_step(t, h)
        elif self._v != 0.0:
            self._braking_step(h)
        self._steps += 1
        if self._state == _QUICK_STOP and self._v == 0.0 and self._fault_pending is not None:
            self._enter_error(self._fault_pending)
        if self._listener is not None and self._steps % self._ratio == 0:
            self._listener(self._t0 + self._steps * h, self._x, self._v)

    def _controlled_step(self, t: float, h: float) -> None:
        """One classical Runge-Kutta step of the closed position loop (see the module notes).

        Written out (no calls): 1.5 million steps per 380 s of rig runs. Each stage: the error
        e = r - x, the demand m (k_i z + k_p e + k_d (r' - x')), saturated at the peak force, the
        integrator held while winding up (saturated and pushing the same way as e). The first
        stage's demand tells the saturation at the step's start; the demand at the step's end
        gives the reported force, the lag r - x the following-error checks.
        """
        m, f_max, low, high, k_i, k_p, k_d = self._loop_constants
        t0, r0, slope = (self._stream.segment(t + 0.5 * h) if self._stream is not None
                         else (t, self._hold, 0.0))
        load = float(self._load_force()) if self._load_force is not None else 0.0

        # the demand (clipped to the travel) at the step's start, middle and end
        half, sixth = h / 2, h / 6
        r_a, v_a = _within(r0 + slope * (t - t0), slope, low, high)
        r_mid, v_mid = _within(r0 + slope * (t + half - t0), slope, low, high)
        r_end, v_end = _within(r0 + slope * (t + h - t0), slope, low, high)
        x, v, z = self._x, self._v, self._z
        gains = (m, f_max, k_i, k_p, k_d, load)
        a0, a1, a2, start_demand = _stage(gains, r_a, v_a, x, v, z)
        b0, b1, b2, _ = _stage(gains, r_mid, v_mid, x + half * a0, v + half * a1, z + half * a2)
        c0, c1, c2, _ = _stage(gains, r_mid, v_mid, x + half * b0, v + half * b1, z + half * b2)
        d0, d1, d2, _ = _stage(gains, r_end, v_end, x + h * c0, v + h * c1, z + h * c2)
        self._x = x = x + sixth * (a0 + 2 * b0 + 2 * c0 + d0)
        self._v = v = v + sixth * (a1 + 2 * b1 + 2 * c1 + d1)
        self._z = z = z + sixth * (a2 + 2 * b2 + 2 * c2 + d2)
        if abs(start_demand) > f_max:  # saturated at the step's start
            self.saturated_time += h
        self._lag = r_end - x
        demand = m * (k_i * z + k_p * (r_end - x) + k_d * (v_end - v))
        self._force = min(max(demand, -f_max), f_max)
        self._warn = abs(self._lag) > self._p.following_error_warning
        self._warned = self._warned or self._warn
        if abs(self._lag) > self._p.following_error_limit:
            self._fault(ErrorCode.FOLLOWING_ERROR)

    def _braking_step(self, h: float) -> None:
        deceleration = self._p.quick_stop_deceleration
        direction = 1.0 if self._v > 0.0 else -1.0
        if abs(self._v) <= deceleration * h:
            self._x += 0.5 * self._v * abs(self._v) / deceleration
            self._v = 0.0
        else:
            self._x += self._v * h - 0.5 * direction * deceleration * h * h
            self._v -= direction * deceleration * h
        self._force = -direction * self._p.moving_mass * deceleration

    # ---- replies ----------------------------------------------------------------------------
    def _send_replies(self, now: float) -> None:
        state, x = self._state, self._x
        operating = state == _OPERATION
        warned, self._warned = self._warned or self._warn, self._warn
        demand = self._reference(now)[0] if operating else x
        status = _HOMED  # plain ints: an IntFlag's | costs a microsecond
        if operating:
            status |= _OPERATION_ENABLED_BIT
        if state == _ERROR or self._fault_pending is not None:
            status |= _ERROR_BIT
        if warned:
            status |= _WARNING_BIT
        if abs(demand - x) < self._p.in_target_window:
            status |= _IN_TARGET_BIT
        if (operating and self._stream is not None) or self._v != 0.0:
            status |= _MOTION_ACTIVE_BIT
        low_byte = (self._echo & 0x0F if operating
                    else self._error_code & 0xFF if state == _ERROR else 0)
        powered = state in (_OPERATION, _QUICK_STOP)
        current = self._force / self._p.force_constant if powered else 0.0
        node = self._ids.node_id
        frames = (
            encode_frame("TxPDO1", {"StatusWord": int(status), "StateLowByte": low_byte,
                                    "MainState": int(state), "ActualPosition": x}, node_id=node),
            encode_frame("TxPDO2", {"DemandPosition": demand, "DemandCurrent": current},
                         node_id=node),
            encode_frame("TxPDO3", {"WarnWord": _POSITION_LAG_BIT if warned else 0,
                                    "LoggedErrorCode": self._logged_error}, node_id=node),
        )
        for frame in frames:
            self._bus.send(frame)
