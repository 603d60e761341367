"""The rig's fast paths agree with the general ones they stand in for (issue 23).

The virtual test bed encodes and decodes its CAN frames with a direct little-endian codec built
from the DBC, deep-copies frames cheaply on the virtual bus, and evaluates the valve's static
characteristic in plain floats. Each must give exactly what cantools, ``copy.deepcopy`` of a
:class:`can.Message` and NumPy give, or fall back to them.
"""
from __future__ import annotations

import copy
import math
import random

import can
import numpy as np
import pytest

from panto.rig import can_protocol as proto
from panto.rig.pneumatics import ValveParameters, _static_pressure


def _random_values(message, rng: random.Random) -> dict[str, float]:
    """Signal values in, at and just beyond each signal's range, some integers, some NaN."""
    values = {}
    for signal in message.signals:
        low, high, scale = signal.minimum, signal.maximum, abs(signal.conversion.scale)
        pick = rng.random()
        if pick < 0.1:
            value = rng.choice([low, high, 0, -0.0])
        elif pick < 0.2:
            value = rng.choice([low, high]) + rng.choice([-1, 1]) * scale * rng.choice(
                [1e-7, 9e-7, 1.1e-6, 0.5, 2.0])
        elif pick < 0.25:
            value = math.nan
        elif pick < 0.5 and scale == 1:
            value = rng.randint(int(low), int(high))
        else:
            value = rng.uniform(low, high) * rng.choice([1.0, 1e-3, 1e-6])
        values[signal.name] = value
    return values


@pytest.mark.parametrize("name", ["NMT", "SYNC", "RxPDO1", "TxPDO1", "TxPDO2", "TxPDO3"])
def test_the_direct_codec_gives_cantools_bytes_and_values(name):
    """Where the direct codec answers, its bytes are cantools' (strict encode) and cantools
    accepts the values; its decoding of random bytes is cantools' (same keys, values, types)."""
    message = proto.load_database().get_message_by_name(name)
    codec = proto._codec(name)
    assert codec is not None  # every frame of the linear motor is little-endian integers
    rng = random.Random(23)
    answered = 0
    for _ in range(3000):
        values = _random_values(message, rng)
        mine = codec.encode(values)
        if mine is not None:
            answered += 1
            assert mine == message.encode(dict(values), scaling=True, strict=True), values
        data = bytes(rng.getrandbits(8) for _ in range(message.length))
        reference = message.decode(data, decode_choices=False, scaling=True)
        decoded = codec.decode(data)
        assert list(decoded.items()) == list(reference.items())
        assert [type(v) for v in decoded.values()] == [type(v) for v in reference.values()]
    assert answered > 1000 or not message.signals


def test_encode_frame_still_refuses_what_cantools_refuses():
    """Out of range, a missing signal, an unknown signal or NaN: ValueError naming the frame."""
    good = {"StatusWord": 1, "StateLowByte": 0, "MainState": 8, "ActualPosition": 0.01}
    for bad in ({**good, "MainState": 256}, {**good, "ActualPosition": 215.0},
                {k: v for k, v in good.items() if k != "MainState"}, {**good, "Other": 1},
                {**good, "ActualPosition": math.nan}):
        with pytest.raises(ValueError, match="TxPDO1"):
            proto.encode_frame("TxPDO1", bad)
    frame = proto.encode_frame("TxPDO1", good)
    name, values = proto.decode_frame(frame)
    assert name == "TxPDO1" and values == pytest.approx(good, abs=0.5e-7)


def test_a_decoded_frame_can_be_changed_without_changing_the_next_one():
    frame = proto.encode_frame("TxPDO3", {"WarnWord": 16, "LoggedErrorCode": 11})
    first = proto.decode_frame(frame)[1]
    first["WarnWord"] = -1
    assert proto.decode_frame(frame)[1] == {"WarnWord": 16, "LoggedErrorCode": 11}


def test_a_frame_deep_copies_like_a_message():
    """Same fields as ``copy.deepcopy`` of the plain message, and an independent data buffer."""
    frame = proto.setpoint_frame(0x3F, master_id=3, count=5, position=-0.0123)
    frame.timestamp, frame.channel = 12.5, "bus-1"
    copied = copy.deepcopy(frame)
    plain = copy.deepcopy(can.Message(
        timestamp=frame.timestamp, arbitration_id=frame.arbitration_id, is_extended_id=False,
        channel=frame.channel, data=frame.data))
    assert isinstance(copied, can.Message) and copied.equals(plain)
    assert copied.data is not frame.data
    copied.data[0] ^= 0xFF
    assert copied.data != frame.data


def test_frames_cross_the_virtual_bus_unchanged():
    channel = f"fast-paths-{id(object())}"
    with can.Bus(interface="virtual", channel=channel) as sender, \
            can.Bus(interface="virtual", channel=channel) as receiver:
        sent = proto.encode_frame("TxPDO2", {"DemandPosition": 0.1234567, "DemandCurrent": -2.5})
        sender.send(sent)
        received = receiver.recv(timeout=1.0)
    assert received.data == sent.data and received.arbitration_id == sent.arbitration_id
    decoded = proto.decode_frame(received)[1]
    assert decoded == proto.load_database().decode_message("TxPDO2", bytes(sent.data),
                                                           decode_choices=False)
    assert decoded["DemandPosition"] == pytest.approx(0.1234567, abs=0.5e-7)
    assert decoded["DemandCurrent"] == -2.5


def test_the_valve_characteristic_in_floats_is_numpys():
    for parameters in (ValveParameters(), ValveParameters(exponent=1.0, dead_band=0.0),
                       ValveParameters(exponent=2.3, saturation_voltage=20.0)):
        voltages = np.concatenate([np.random.default_rng(4).uniform(-5.0, 30.0, 20000),
                                   [0.0, parameters.dead_band, parameters.saturation_voltage,
                                    parameters.max_voltage]])
        for voltage in voltages.tolist():
            assert _static_pressure(parameters, voltage) == float(
                parameters.static_pressure(voltage))
