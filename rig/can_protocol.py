"""CAN protocol of the rig's linear motor: frames, words, states and error codes.

The thesis' rig drives its linear motor over CAN in the drive's *position-stream* mode at 250 Hz
(Kalteis, "Physically based modelling of a high-speed pantograph", section 3.1): every 4 ms the
master sends the setpoint frame RxPDO1 and then a SYNC frame, so every second frame is a
synchronisation frame. The drive (LinMot type, CANopen CiA 301 with the vendor's profile) applies
a received RxPDO at the next SYNC and answers every SYNC with TxPDO1..3.

The frame layout lives in ``linear_motor.dbc`` next to this module, read once with cantools, so the
driver (:mod:`panto.rig.drive`), the emulator (:mod:`panto.rig.drive_emulator`) and a user's bus analyser all
share one definition. The DBC file carries the identifiers of the default node 63; for another node
``n`` :class:`FrameIds` shifts the PDO identifiers (``0x180/0x280/0x380 + n``, ``0x200 + n``), and
:func:`encode_frame` / :func:`decode_frame` take the node id.

Units (SI inside): positions are metres on the Python side; on the bus they are signed 32-bit
integers in 0.1 um (DBC factor 1e-7, so +-214 m). The demand current is an integer in mA on the bus
and amperes on the Python side (DBC factor 1e-3).

=================  =====  ==============================================================
frame              id     fields (little-endian)
=================  =====  ==============================================================
NMT                0x000  command u8 (1 = start remote node), node id u8
SYNC               0x080  no data
RxPDO1 (setpoint)  0x23F  control word u16, header u16 (master 15-8, sub 7-4, count 3-0),
                          parameter i32 (030x: position, 0.1 um)
TxPDO1             0x1BF  status word u16, state variable u16 (main state in the high byte),
                          actual position i32 (0.1 um)
TxPDO2             0x2BF  demand position i32 (0.1 um), demand current i32 (mA)
TxPDO3             0x3BF  warn word u16, logged error code u16
=================  =====  ==============================================================
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from copy import deepcopy
from dataclasses import dataclass
from enum import IntEnum, IntFlag
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import can

if TYPE_CHECKING:
    from cantools.database.can import Database

DBC_PATH = Path(__file__).with_name("linear_motor.dbc")
DEFAULT_NODE_ID = 63
POSITION_RESOLUTION = 1e-7
"""Metres per raw position unit (0.1 um)."""
_INT32_LIMITS = (-(2**31), 2**31 - 1)

STREAM_MASTER_ID = 0x03
"""Master id of the streaming motion commands (header bits 15-8)."""


class NmtCommand(IntEnum):
    """First data byte of the NMT frame (CiA 301)."""

    START_REMOTE_NODE = 0x01
    STOP_REMOTE_NODE = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class ControlWord(IntFlag):
    """Control-word bits of the drive (bits 2, 4 and 5 are active low)."""

    SWITCH_ON = 1 << 0
    VOLTAGE_ENABLE = 1 << 1
    NOT_QUICK_STOP = 1 << 2
    ENABLE_OPERATION = 1 << 3
    NOT_ABORT = 1 << 4
    NOT_FREEZE = 1 << 5
    ERROR_ACKNOWLEDGE = 1 << 7
    HOME = 1 << 11


CONTROL_WORD_OFF = ControlWord(0)
"""Voltage and switch-on off: the drive leaves operation (state 2 after a stop)."""
CONTROL_WORD_READY = ControlWord(0x003E)
"""Everything but switch on: the drive waits in state 2."""
CONTROL_WORD_RUNNING = ControlWord(0x003F)
"""The running value: switch on, voltage, no quick stop, enable operation, no abort, no freeze."""


class StatusWord(IntFlag):
    """Status-word bits reported in TxPDO1."""

    OPERATION_ENABLED = 1 << 0
    ERROR = 1 << 3
    WARNING = 1 << 7
    IN_TARGET_POSITION = 1 << 10
    HOMED = 1 << 11
    FATAL_ERROR = 1 << 12
    MOTION_ACTIVE = 1 << 13


class WarnWord(IntFlag):
    """Warn-word bits reported in TxPDO3."""

    POSITION_LAG = 1 << 4


class MainState(IntEnum):
    """Main state: the high byte of the state variable in TxPDO1."""

    READY_TO_SWITCH_ON = 2
    ERROR = 4
    READY_TO_OPERATE = 6
    OPERATION_ENABLED = 8
    HOMING = 9
    QUICK_STOP = 14


class StreamCommand(IntEnum):
    """Sub id (header bits 7-4) of the streaming motion commands of master id 3."""

    POSITION = 0x0
    POSITION_VELOCITY = 0x1
    POSITION_VELOCITY_ACCELERATION = 0x4
    STOP = 0xF


class ErrorCode(IntEnum):
    """Error codes: the drive's (one byte, reported on the bus) and the driver's own.

    Codes above 0xFFFF never appear on the bus: the driver uses them for faults it detects
    itself (missing replies, bus errors).
    """

    FOLLOWING_ERROR = 0x0B
    BUFFER_OVERFLOW = 0x82
    BUFFER_UNDERFLOW = 0x83
    MASTER_TOO_FAST = 0x84
    MASTER_TOO_SLOW = 0x85
    MOTION_COMMAND_WRONG_STATE = 0x86
    MISSING_REPLIES = 0x1_0001
    BUS_ERROR = 0x1_0002


_ERROR_MEANINGS: Mapping[int, str] = {
    0: "no error",
    ErrorCode.FOLLOWING_ERROR: "following error: position lag always too big",
    ErrorCode.BUFFER_OVERFLOW: "stream buffer overflow: setpoints arrive faster than the "
    "drive consumes them",
    ErrorCode.BUFFER_UNDERFLOW: "stream buffer underflow: the next setpoint did not arrive in time",
    ErrorCode.MASTER_TOO_FAST: "stream master too fast: setpoint interval below the allowed range",
    ErrorCode.MASTER_TOO_SLOW: "stream master too slow: setpoint interval above the allowed range",
    ErrorCode.MOTION_COMMAND_WRONG_STATE: "motion command in wrong state: the drive was not in "
    "operation enabled (state 8)",
    ErrorCode.MISSING_REPLIES: "missing replies: the drive did not answer the SYNC frames",
    ErrorCode.BUS_ERROR: "bus error: the CAN interface reported an error",
}


def describe_error(code: int) -> str:
    """Meaning of an error code, e.g. ``describe_error(0x0B)`` -> ``"following error: ..."``."""
    meaning = _ERROR_MEANINGS.get(int(code))
    return meaning if meaning is not None else f"unknown error code 0x{int(code):02X}"


def describe_state(state: int) -> str:
    """Name of a main state, e.g. ``describe_state(8)`` -> ``"operation enabled"``."""
    try:
        return MainState(state).name.lower().replace("_", " ")
    except ValueError:
        return f"unknown state {int(state)}"


def check_node_id(node_id: int) -> int:
    """Return `node_id` if it is a valid CANopen node id (1..127), else raise ValueError."""
    if isinstance(node_id, bool) or not isinstance(node_id, int) or not 1 <= node_id <= 127:
        raise ValueError(f"node_id must be an integer in 1..127, got {node_id!r}")
    return node_id


@dataclass(frozen=True)
class FrameIds:
    """CAN identifiers used with one drive node.

    Use :meth:`for_node`; the PDO identifiers are the CiA 301 defaults ``base + node_id``.
    """

    node_id: int
    nmt: int
    sync: int
    rxpdo1: int
    txpdo1: int
    txpdo2: int
    txpdo3: int

    @classmethod
    def for_node(cls, node_id: int = DEFAULT_NODE_ID) -> FrameIds:
        """Identifiers for `node_id` (1..127)."""
        n = check_node_id(node_id)
        return cls(n, 0x000, 0x080, 0x200 + n, 0x180 + n, 0x280 + n, 0x380 + n)

    def message_name(self, arbitration_id: int) -> str | None:
        """DBC message name of a frame identifier, or None for a foreign frame."""
        return _names_by_id(self).get(arbitration_id)


@lru_cache(maxsize=128)
def _names_by_id(ids: FrameIds) -> dict[int, str]:
    return {ids.nmt: "NMT", ids.sync: "SYNC", ids.rxpdo1: "RxPDO1", ids.txpdo1: "TxPDO1",
            ids.txpdo2: "TxPDO2", ids.txpdo3: "TxPDO3"}


@lru_cache(maxsize=128)
def _ids_by_name(ids: FrameIds) -> dict[str, int]:
    return {name: identifier for identifier, name in _names_by_id(ids).items()}


@lru_cache(maxsize=1)
def load_database() -> Database:
    """The linear motor's cantools database, read once from :data:`DBC_PATH`."""
    import cantools

    return cantools.database.load_file(str(DBC_PATH), strict=True)


def position_to_raw(position: float, what: str = "position") -> int:
    """Bus integer (0.1 um) of a position in metres; ValueError if not finite or out of i32."""
    value = float(position)
    if not math.isfinite(value):
        raise ValueError(f"{what} must be finite, got {position!r}")
    raw = round(value / POSITION_RESOLUTION)
    if not _INT32_LIMITS[0] <= raw <= _INT32_LIMITS[1]:
        raise ValueError(f"{what} = {value} m is outside the bus range of +-214.7 m")
    return raw


class Frame(can.Message):
    """A :class:`can.Message` whose deep copy is cheap (same fields, a fresh data bytearray).

    python-can's virtual bus deep-copies every frame for every receiver; the generic
    ``copy.deepcopy`` of the data bytearray costs most of a frame's trip through the bus.
    """

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, object] | None) -> Frame:
        channel = self.channel
        return Frame(timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                     is_extended_id=self.is_extended_id, is_remote_frame=self.is_remote_frame,
                     is_error_frame=self.is_error_frame,
                     channel=channel if channel is None or isinstance(channel, (str, int))
                     else deepcopy(channel, memo),
                     dlc=self.dlc, data=bytearray(self.data), is_fd=self.is_fd, is_rx=self.is_rx,
                     bitrate_switch=self.bitrate_switch,
                     error_state_indicator=self.error_state_indicator)


@lru_cache(maxsize=128)
def _frame_ids(node_id: int) -> FrameIds:
    return FrameIds.for_node(node_id)


class _IntelCodec:
    """Encoder/decoder of one DBC message whose signals are all little-endian integers (the
    linear motor's frames), exactly as cantools does it (same conversions, same strict range
    check) but without its per-call generality. Anything unusual (a missing or foreign signal,
    a choice name, a value out of range) returns None: the caller then asks cantools, which
    encodes it or raises its own error."""

    def __init__(self, message) -> None:
        self.length = message.length
        self.names = frozenset(signal.name for signal in message.signals)
        self.signals = tuple(
            (signal.name, signal.start, signal.length, signal.is_signed, signal.conversion,
             -math.inf if signal.minimum is None
             else signal.minimum - abs(signal.conversion.scale) * 1e-6,
             math.inf if signal.maximum is None
             else signal.maximum + abs(signal.conversion.scale) * 1e-6)
            for signal in message.signals)

    @classmethod
    def applies_to(cls, message) -> bool:
        """True if every signal of `message` is a little-endian integer and nothing multiplexes."""
        return not message.is_multiplexed() and all(
            signal.byte_order == "little_endian" and not signal.is_float
            and not signal.conversion.is_float for signal in message.signals)

    def encode(self, values: Mapping[str, float]) -> bytes | None:
        """The data bytes, or None when cantools must decide."""
        if len(values) != len(self.names) or not self.names.issuperset(values):
            return None
        word = 0
        for name, start, length, signed, conversion, low, high in self.signals:
            value = values[name]
            if not isinstance(value, (int, float)) or not low <= value <= high:
                return None
            raw = conversion.numeric_scaled_to_raw(value)
            top = 1 << (length - 1 if signed else length)
            if not (-top if signed else 0) <= raw < top:
                return None
            word |= (raw & ((1 << length) - 1)) << start
        return word.to_bytes(self.length, "little")

    def decode(self, data: bytes) -> dict[str, float]:
        """The physical signal values of `data` (``len(data) == self.length``)."""
        word = int.from_bytes(data, "little")
        decoded = {}
        for name, start, length, signed, conversion, _, _ in self.signals:
            raw = (word >> start) & ((1 << length) - 1)
            if signed and raw >> (length - 1):
                raw -= 1 << length
            decoded[name] = conversion.raw_to_scaled(raw, False)
        return decoded


@lru_cache(maxsize=None)
def _codec(name: str) -> _IntelCodec | None:
    message = load_database().get_message_by_name(name)
    return _IntelCodec(message) if _IntelCodec.applies_to(message) else None


@lru_cache(maxsize=4096)
def _encoded(name: str, items: tuple[tuple[str, float], ...]) -> bytes:
    """The DBC data bytes of `name` with the signal values `items` (a pure function, so the
    frames that repeat - SYNC, NMT, an unchanged TxPDO3 - are encoded once)."""
    values = dict(items)
    codec = _codec(name)
    data = codec.encode(values) if codec is not None else None
    if data is None:
        data = load_database().get_message_by_name(name).encode(values, scaling=True,
                                                                 strict=True)
    return data


@lru_cache(maxsize=4096)
def _decoded(name: str, data: bytes) -> dict[str, float]:
    """The signal values of `name`'s data bytes (pure; callers receive a copy)."""
    codec = _codec(name)
    if codec is not None:
        return codec.decode(data)
    return load_database().get_message_by_name(name).decode(data, decode_choices=False,
                                                            scaling=True)


def encode_frame(name: str, values: Mapping[str, float] | None = None, *,
                 node_id: int = DEFAULT_NODE_ID) -> can.Message:
    """Encode the DBC message `name` for `node_id` into a python-can message.

    `values` maps signal names to physical values (positions in m, current in A). Missing or
    out-of-range signals raise ValueError naming the message.
    """
    ids = _frame_ids(node_id)
    identifier = _ids_by_name(ids).get(name)
    if identifier is None:
        raise ValueError(f"unknown frame {name!r}; known: {sorted(_names_by_id(ids).values())}")
    try:
        items = tuple(values.items()) if values else ()
        hash(items)
    except TypeError:  # unhashable values: encode without the cache
        items = None
    try:
        if items is None:
            data = load_database().get_message_by_name(name).encode(
                dict(values or {}), scaling=True, strict=True)
        else:
            data = _encoded(name, items)
    except Exception as error:  # cantools raises EncodeError / KeyError with terse texts
        raise ValueError(f"cannot encode {name} with {dict(values or {})}: {error}") from None
    return Frame(arbitration_id=identifier, data=data, is_extended_id=False)


def decode_frame(frame: can.Message, *, node_id: int = DEFAULT_NODE_ID
                 ) -> tuple[str, dict[str, float]] | None:
    """Decode a frame of `node_id`'s protocol: ``(message name, {signal: physical value})``.

    Returns None for frames that are not part of this node's protocol (other identifiers,
    extended or remote frames). A frame with the wrong length raises ValueError.
    """
    if frame.is_extended_id or frame.is_remote_frame or frame.is_error_frame:
        return None
    name = _frame_ids(node_id).message_name(frame.arbitration_id)
    if name is None:
        return None
    message = load_database().get_message_by_name(name)
    if len(frame.data) != message.length:
        raise ValueError(f"frame 0x{frame.arbitration_id:03X} ({name}) has {len(frame.data)} "
                         f"data bytes, expected {message.length}")
    return name, dict(_decoded(name, bytes(frame.data)))


def nmt_frame(command: NmtCommand, node_id: int = DEFAULT_NODE_ID) -> can.Message:
    """NMT frame for one node (``node_id`` 0 addresses all nodes)."""
    target = 0 if node_id == 0 else check_node_id(node_id)
    return encode_frame("NMT", {"NmtCommand": int(command), "NmtNodeId": target})


def sync_frame() -> can.Message:
    """The SYNC frame (identifier 0x080, no data)."""
    return encode_frame("SYNC")


def setpoint_frame(control_word: int, *, node_id: int = DEFAULT_NODE_ID, master_id: int = 0,
                   sub_id: int = 0, count: int = 0, position: float = 0.0) -> can.Message:
    """RxPDO1: control word, motion-command header and position parameter [m].

    ``master_id=0`` is "no motion command": the drive only takes the control word and the count.
    """
    for what, value, top in (("master_id", master_id, 255), ("sub_id", sub_id, 15),
                             ("count", count, 15), ("control_word", control_word, 0xFFFF)):
        if not 0 <= int(value) <= top:
            raise ValueError(f"{what} must be in 0..{top}, got {value!r}")
    raw = position_to_raw(position)
    return encode_frame("RxPDO1", {
        "ControlWord": int(control_word), "MotionCommandCount": int(count),
        "MotionCommandSubId": int(sub_id), "MotionCommandMasterId": int(master_id),
        "TargetPosition": raw * POSITION_RESOLUTION}, node_id=node_id)
