"""Driver of the rig's linear motor: CANopen position stream at 250 Hz over python-can.

The thesis' rig addresses its linear motor over CAN at 250 Hz in the drive's *position-stream* mode,
every second frame being a SYNC (Kalteis, section 3.1). :class:`LinearMotorDriver` is that master:

* :meth:`~LinearMotorDriver.start`: NMT "start remote node", acknowledge a pending error (rising
  edge of control-word bit 7), then switch on and enable operation through the drive's state
  machine (2 -> 6 -> 8), checking the reply after every stage.
* :meth:`~LinearMotorDriver.stream`: one cycle: RxPDO1 with the position-stream command 030x and
  the next command-count nibble, then SYNC. The caller keeps the period (absolute deadlines, see
  :class:`panto.rig.clock.Ticker`).
* :meth:`~LinearMotorDriver.check`: reads the replies without blocking and raises
  :class:`DriveFault` with the drive's error code and its meaning when the drive reports an error,
  when replies are missing for ``reply_timeout_cycles`` SYNCs, or when the bus fails
  (:class:`BusFault`).

Exceptions (a typed tree, as python-can does)::

    RigError (RuntimeError)
    +-- DriveFault        code, meaning, feedback: the drive cannot go on
    |   +-- BusFault      the CAN interface raised (code ErrorCode.BUS_ERROR)
    +-- ProtocolError     the drive does not behave as the protocol says (malformed frame,
                          state machine not following), or the driver is used out of order

A fault is sticky: once raised, :meth:`~LinearMotorDriver.check` and
:meth:`~LinearMotorDriver.stream` raise it again until :meth:`~LinearMotorDriver.start` succeeds.
Replies are read with a non-blocking drain (``bus.recv(timeout=0)``), so a cycle never waits on the
bus. The bus is any python-can bus: the virtual bus in tests, socketcan/pcan/kvaser on the rig by
configuration only (:func:`open_bus`).

Typical loop (``driver.check()`` before ``driver.stream()``: by then the replies to the previous
SYNC are in)::

    ticker = Ticker(clock, driver.period)
    driver.start()
    for x in positions:
        ticker.wait()
        driver.check()
        driver.stream(x)
    driver.stop_streaming()
    driver.disable()
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

import can

from panto.rig.can_protocol import (
    CONTROL_WORD_OFF,
    CONTROL_WORD_READY,
    CONTROL_WORD_RUNNING,
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
    describe_error,
    describe_state,
    load_database,
    nmt_frame,
    position_to_raw,
    setpoint_frame,
    sync_frame,
)
from panto.rig.clock import Clock, RealClock


@dataclass(frozen=True)
class DriveFeedback:
    """The drive's latest replies (TxPDO1..3), decoded, in SI units.

    Attributes
    ----------
    time : clock time at which the TxPDO1 was read [s].
    status_word : decoded status bits.
    main_state : main state (:class:`panto.rig.can_protocol.MainState` values).
    command_count_echo : count nibble of the last executed motion command (state 8), else None.
    actual_position : slider position [m].
    demand_position : interpolated demand position [m].
    demand_current : motor current demand [A].
    warn_word : decoded warn bits (bit 4 position-lag pre-warning).
    error_code : in state 4 the error code of the state variable, else the logged error code.
    replies : number of TxPDO1 frames received since :meth:`LinearMotorDriver.start`.
    """

    time: float
    status_word: StatusWord
    main_state: int
    command_count_echo: int | None
    actual_position: float
    demand_position: float
    demand_current: float
    warn_word: WarnWord
    error_code: int
    replies: int

    @property
    def position_lag(self) -> float:
        """Demand minus actual position [m]."""
        return self.demand_position - self.actual_position

    @property
    def state_name(self) -> str:
        """Name of the main state."""
        return describe_state(self.main_state)

    @property
    def error_meaning(self) -> str:
        """Meaning of :attr:`error_code`."""
        return describe_error(self.error_code)


class RigError(RuntimeError):
    """Base of the rig's errors."""


class ProtocolError(RigError):
    """The drive or the driver's caller did not follow the protocol."""


class DriveFault(RigError):
    """The drive cannot go on: the drive's error code, or a driver-side code (missing replies).

    Attributes
    ----------
    code : error code (:class:`panto.rig.can_protocol.ErrorCode`; > 0xFFFF: detected by the driver).
    meaning : what the code means, with details.
    feedback : the drive's last replies (None if there were none).
    """

    def __init__(self, code: int, meaning: str, feedback: DriveFeedback | None = None) -> None:
        self.code, self.meaning, self.feedback = int(code), meaning, feedback
        where = "" if feedback is None else (
            f" (state {feedback.main_state} {feedback.state_name} at t = {feedback.time:.4f} s)")
        driver_side = self.code in (ErrorCode.MISSING_REPLIES, ErrorCode.BUS_ERROR)
        label = ErrorCode(self.code).name if driver_side else f"0x{self.code:02X}"
        super().__init__(f"drive fault {label}: {meaning}{where}")

    def __reduce__(self) -> tuple[Any, ...]:
        return DriveFault, (self.code, self.meaning, self.feedback)


class BusFault(DriveFault):
    """The CAN interface raised an error (code :attr:`ErrorCode.BUS_ERROR`)."""

    def __init__(self, meaning: str, feedback: DriveFeedback | None = None) -> None:
        super().__init__(ErrorCode.BUS_ERROR, meaning, feedback)

    def __reduce__(self) -> tuple[Any, ...]:
        return BusFault, (self.meaning, self.feedback)


def open_bus(interface: str | None = None, channel: Any = None, **options: Any) -> can.BusABC:
    """Open a python-can bus; what is not given comes from python-can's config file or environment.

    ``open_bus()`` on the rig reads ``CAN_INTERFACE`` / ``CAN_CHANNEL`` / ``CAN_BITRATE`` or
    ``~/.canrc``; ``open_bus("virtual", "rig")`` is the in-process bus of tests and the emulator.
    Failures raise :class:`BusFault` naming the configuration.
    """
    kwargs = dict(options)
    if interface is not None:
        kwargs["interface"] = interface
    if channel is not None:
        kwargs["channel"] = channel
    try:
        return can.Bus(**kwargs)
    except (can.CanError, OSError, ValueError, ImportError) as error:
        raise BusFault(f"cannot open CAN bus with {kwargs or 'the python-can configuration'}: "
                       f"{error} (set interface/channel, CAN_INTERFACE/CAN_CHANNEL or ~/.canrc)"
                       ) from error


class LinearMotorDriver:
    """Master of the linear motor's position stream (see the module notes).

    Parameters
    ----------
    bus
        A python-can bus (not shut down by :meth:`close` unless ``own_bus``).
    node_id
        The drive's CANopen node id.
    clock
        Time source for the waits of :meth:`start`/:meth:`disable` and for feedback time stamps;
        default :class:`panto.rig.clock.RealClock`.
    period
        Cycle period used by :meth:`start`/:meth:`disable` [s] (the stream's period is the
        caller's: the drive measures it).
    reply_timeout_cycles
        SYNCs without a TxPDO1 reply after which :meth:`check` raises "missing replies".
    state_timeout_cycles
        Cycles a start-up stage may take before :class:`ProtocolError`.
    position_limits
        Optional (min, max) [m]; :meth:`stream` refuses positions outside with ValueError.
    own_bus
        Shut the bus down in :meth:`close`.
    """

    def __init__(self, bus: can.BusABC, *, node_id: int = DEFAULT_NODE_ID,
                 clock: Clock | None = None, period: float = 0.004,
                 reply_timeout_cycles: int = 3, state_timeout_cycles: int = 50,
                 position_limits: tuple[float, float] | None = None,
                 own_bus: bool = False) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be a finite number > 0 s, got {period!r}")
        for name, value in (("reply_timeout_cycles", reply_timeout_cycles),
                            ("state_timeout_cycles", state_timeout_cycles)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if position_limits is not None and not position_limits[0] < position_limits[1]:
            raise ValueError(f"position_limits must be (min, max), got {position_limits!r}")
        self._bus, self._own_bus = bus, own_bus
        self._ids = FrameIds.for_node(node_id)
        self._clock = clock if clock is not None else RealClock()
        self._period, self._limits = float(period), position_limits
        self._reply_timeout, self._state_timeout = reply_timeout_cycles, state_timeout_cycles
        self._count, self._deadline = 0, 0.0
        load_database()  # parse the DBC now, not in the first cycle
        self._reset_session()

    @classmethod
    def open(cls, interface: str | None = None, channel: Any = None, *,
             bus_options: dict[str, Any] | None = None, **driver_options: Any
             ) -> LinearMotorDriver:
        """A driver on a bus opened with :func:`open_bus`, shut down again by :meth:`close`."""
        bus = open_bus(interface, channel, **(bus_options or {}))
        return cls(bus, own_bus=True, **driver_options)

    def _reset_session(self) -> None:
        self._fault: DriveFault | None = None
        self._enabled = self._streaming = False
        self._pdo: dict[str, dict[str, float]] = {}
        self._reply_time = math.nan
        self._replies = self._syncs_since_reply = 0
        self._control_word = CONTROL_WORD_OFF
        self.acknowledged_error: int | None = None
        """Error code that :meth:`start` found pending and acknowledged (None if none)."""

    # ---- properties -------------------------------------------------------------------------
    @property
    def node_id(self) -> int:
        """The drive's node id."""
        return self._ids.node_id

    @property
    def period(self) -> float:
        """Cycle period [s]."""
        return self._period

    @property
    def command_count(self) -> int:
        """Count nibble of the last motion command sent."""
        return self._count

    @property
    def enabled(self) -> bool:
        """True between a successful :meth:`start` and :meth:`disable` or a fault."""
        return self._enabled

    @property
    def streaming(self) -> bool:
        """True after :meth:`stream` until :meth:`stop_streaming`, :meth:`disable` or a fault."""
        return self._streaming

    # ---- sending and receiving --------------------------------------------------------------
    def _send(self, frame: can.Message, what: str) -> None:
        try:
            self._bus.send(frame, timeout=self._period)
        except (can.CanError, OSError) as error:
            self._raise(BusFault(f"bus error while sending {what}: {error}", self._latest()),
                        error)

    def _raise(self, fault: DriveFault, cause: BaseException | None = None) -> NoReturn:
        self._fault, self._enabled, self._streaming = fault, False, False
        raise fault from cause

    def _send_cycle(self, control_word: int, *, sub_id: int | None = None,
                    position: float = 0.0) -> None:
        """RxPDO1 (a new motion command when `sub_id` is given) followed by SYNC."""
        master = 0
        if sub_id is not None:
            self._count, master = (self._count + 1) % 16, STREAM_MASTER_ID
        self._control_word = control_word
        self._send(setpoint_frame(control_word, node_id=self.node_id, master_id=master,
                                  sub_id=sub_id or 0, count=self._count, position=position),
                   "RxPDO1")
        self._send(sync_frame(), "SYNC")
        self._syncs_since_reply += 1

    def _drain(self) -> None:
        """Read every waiting frame without blocking; keep the latest TxPDO1..3 of our node."""
        while True:
            try:
                frame = self._bus.recv(timeout=0.0)
            except (can.CanError, OSError) as error:
                self._raise(BusFault(f"bus error while receiving: {error}", self._latest()), error)
            if frame is None:
                return
            try:
                decoded = decode_frame(frame, node_id=self.node_id)
            except ValueError as error:
                raise ProtocolError(f"node {self.node_id}: {error}") from None
            if decoded is None or not decoded[0].startswith("TxPDO"):
                continue
            self._pdo[decoded[0]] = decoded[1]
            if decoded[0] == "TxPDO1":
                self._replies += 1
                self._syncs_since_reply = 0
                self._reply_time = self._clock.now()

    def _latest(self) -> DriveFeedback | None:
        first = self._pdo.get("TxPDO1")
        if first is None:
            return None
        second = self._pdo.get("TxPDO2", {"DemandPosition": math.nan, "DemandCurrent": math.nan})
        third = self._pdo.get("TxPDO3", {"WarnWord": 0, "LoggedErrorCode": 0})
        state, low = int(first["MainState"]), int(first["StateLowByte"])
        return DriveFeedback(
            time=self._reply_time, status_word=StatusWord(int(first["StatusWord"])),
            main_state=state,
            command_count_echo=low & 0x0F if state == MainState.OPERATION_ENABLED else None,
            actual_position=float(first["ActualPosition"]),
            demand_position=float(second["DemandPosition"]),
            demand_current=float(second["DemandCurrent"]),
            warn_word=WarnWord(int(third["WarnWord"])),
            error_code=low if state == MainState.ERROR else int(third["LoggedErrorCode"]),
            replies=self._replies)

    def feedback(self) -> DriveFeedback | None:
        """The drive's latest replies (after a non-blocking read), None before the first one."""
        self._drain()
        return self._latest()

    def check(self) -> DriveFeedback | None:
        """Read the replies and raise :class:`DriveFault` if the drive cannot go on.

        Raises when the drive reports state 4 (error) or a quick stop with a logged error, when
        ``reply_timeout_cycles`` SYNCs went unanswered, or on a bus error (:class:`BusFault`).
        Otherwise returns the latest feedback.
        """
        if self._fault is not None:
            raise self._fault
        self._drain()
        latest = self._latest()
        if latest is not None and (latest.main_state == MainState.ERROR or (
                latest.main_state == MainState.QUICK_STOP and latest.error_code)):
            self._raise(DriveFault(latest.error_code, latest.error_meaning, latest))
        if self._syncs_since_reply >= self._reply_timeout:
            self._raise(DriveFault(
                ErrorCode.MISSING_REPLIES,
                f"{describe_error(ErrorCode.MISSING_REPLIES)}: no TxPDO1 from node "
                f"{self.node_id} for {self._syncs_since_reply} SYNC periods", latest))
        return latest

    # ---- operation --------------------------------------------------------------------------
    def start(self) -> DriveFeedback:
        """Bring the drive into operation (state 8); return its feedback.

        NMT start remote node; read the state (once a running quick stop has ended); in state 4
        acknowledge the error with a rising edge of control-word bit 7; then control word 0x003E
        (state 2) and 0x003F (states 6, 8).
        Raises :class:`DriveFault` (missing replies, an error that cannot be acknowledged, an
        error during start-up), :class:`BusFault`, or :class:`ProtocolError` when a stage does
        not reach its state within ``state_timeout_cycles``.
        """
        self._reset_session()
        self._deadline = self._clock.now()
        self._send(nmt_frame(NmtCommand.START_REMOTE_NODE, self.node_id), "NMT start")
        state = self._await(CONTROL_WORD_OFF, lambda s: s != MainState.QUICK_STOP,
                            "reading the state after NMT start")
        if state.main_state == MainState.ERROR:
            self.acknowledged_error = state.error_code
            try:
                self._await(ControlWord.ERROR_ACKNOWLEDGE, lambda s: s != MainState.ERROR,
                            f"acknowledging error 0x{state.error_code:02X}", error_is_fault=False)
            except ProtocolError:
                self._raise(DriveFault(state.error_code, f"{state.error_meaning}; the error "
                                       "could not be acknowledged", self._latest()))
        self._await(CONTROL_WORD_READY, lambda s: s == MainState.READY_TO_SWITCH_ON,
                    "switching off (control word 0x003E)")
        state = self._await(CONTROL_WORD_RUNNING, lambda s: s == MainState.OPERATION_ENABLED,
                            "enabling operation (control word 0x003F)")
        self._enabled = True
        return state

    def _await(self, control_word: int, reached: Callable[[int], bool], stage: str, *,
               error_is_fault: bool = True) -> DriveFeedback:
        """Send `control_word` each cycle until a reply's main state satisfies `reached`."""
        latest = None
        for _ in range(self._state_timeout):
            self._send_cycle(control_word)
            # next deadline, but after a stall at least half a period for the reply (no burst)
            self._deadline = max(self._deadline + self._period,
                                 self._clock.now() + 0.5 * self._period)
            self._clock.sleep_until(self._deadline)
            self._drain()
            if self._syncs_since_reply >= self._reply_timeout:
                self._raise(DriveFault(ErrorCode.MISSING_REPLIES,
                                       f"no reply from node {self.node_id} while {stage} "
                                       f"(is the node id right and the drive powered?)",
                                       self._latest()))
            latest = self._latest()
            if latest is None or self._syncs_since_reply > 0:
                continue
            if reached(latest.main_state):
                return latest
            if error_is_fault and latest.main_state == MainState.ERROR:
                self._raise(DriveFault(latest.error_code,
                                       f"{latest.error_meaning} (while {stage})", latest))
        seen = "no reply" if latest is None else f"state {latest.main_state} ({latest.state_name})"
        raise ProtocolError(f"node {self.node_id}: {stage} did not complete within "
                            f"{self._state_timeout} cycles; last {seen}")

    def stream(self, position_m: float) -> None:
        """Send one stream cycle: RxPDO1 with 030x (next count) and `position_m` [m], then SYNC."""
        if self._fault is not None:
            raise self._fault
        if not self._enabled:
            raise ProtocolError("stream() needs a drive in operation: call start() first")
        position_to_raw(position_m, "stream position")
        if self._limits is not None and not self._limits[0] <= position_m <= self._limits[1]:
            raise ValueError(f"stream position {position_m} m is outside the position limits "
                             f"{self._limits}")
        self._drain()
        self._send_cycle(CONTROL_WORD_RUNNING, sub_id=StreamCommand.POSITION,
                         position=float(position_m))
        self._streaming = True

    def stop_streaming(self) -> None:
        """Send the stop-streaming command 03Fx (with SYNC); no-op unless the drive is enabled."""
        if self._enabled and self._fault is None:
            self._send_cycle(CONTROL_WORD_RUNNING, sub_id=StreamCommand.STOP)
        self._streaming = False

    def disable(self) -> DriveFeedback | None:
        """Stop streaming and switch the drive off (control word 0); return its feedback.

        Waits until the drive has left states 6, 8 and 14 (a drive in error counts as off).
        """
        self.stop_streaming()
        self._enabled = False
        self._deadline = self._clock.now()
        off = self._await(CONTROL_WORD_OFF, lambda s: s not in (6, 8, 14), "switching off",
                          error_is_fault=False)
        return off

    def close(self) -> None:
        """Switch the drive off if it is on (errors ignored) and release an owned bus."""
        try:
            if self._enabled and self._fault is None:
                self.disable()
        except RigError:
            pass
        finally:
            if self._own_bus:
                self._bus.shutdown()

    def __enter__(self) -> LinearMotorDriver:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
