import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_protocol import (
    AXIS_BASE,
    AXIS_STRIDE,
    MAGIC,
    REGISTER_MAP,
    ProtocolError,
    decode,
    decode_block,
    encode,
    encode_values,
    register,
)
from firmware_protocol.codec import _RANGES


def test_identification_block_is_fixed():
    assert register("MAGIC").address() == 0 and MAGIC == 0x4854
    assert register("PROTOCOL_VERSION").address() == 1
    assert register("AXIS_COUNT").address() == 2


def test_per_axis_addresses():
    reg = register("TARGET_ANGLE")
    assert reg.address(0) == AXIS_BASE
    assert reg.address(1) == AXIS_BASE + AXIS_STRIDE
    with pytest.raises(ValueError):
        reg.address(None)


def test_int32_is_high_word_first_and_signed():
    assert encode("TARGET_ANGLE", -0.001) == [0xFFFF, 0xFFFF]
    assert encode("TARGET_ANGLE", 65.536) == [0x0001, 0x0000]
    assert decode("TARGET_ANGLE", [0xFFFF, 0xFFFF]) == pytest.approx(-0.001)


def test_out_of_range_and_non_finite_values_are_refused():
    with pytest.raises(ProtocolError, match="outside"):
        encode("HEARTBEAT_TIMEOUT", 7000.0)
    with pytest.raises(ProtocolError, match="finite"):
        encode("TARGET_ANGLE", float("nan"))
    with pytest.raises(ProtocolError):
        decode("TARGET_ANGLE", [1])
    with pytest.raises(ProtocolError):
        decode("STATUS", [0x10000])


@given(st.sampled_from(REGISTER_MAP), st.data())
def test_round_trip_every_register(reg, data):
    lo, hi = _RANGES[reg.type]
    raw = data.draw(st.integers(lo, hi))
    value = raw * reg.scale if reg.scale != 1 else raw
    words = encode(reg, value)
    assert len(words) == reg.words and all(0 <= w <= 0xFFFF for w in words)
    back = decode(reg, words)
    assert back == pytest.approx(value, abs=reg.scale / 2)
    assert encode(reg, back) == words


@given(st.floats(-180, 180, allow_nan=False))
def test_angles_quantise_to_a_thousandth(angle):
    assert abs(decode("ACTUAL_ANGLE", encode("ACTUAL_ANGLE", angle)) - angle) <= 0.0005 + 1e-12


def test_decode_block_and_encode_values():
    writes = encode_values({"TARGET_ANGLE": 12.5, "MODE": 2}, axis=1)
    start = AXIS_BASE + AXIS_STRIDE
    words = [writes.get(start + i, 0) for i in range(AXIS_STRIDE)]
    v = decode_block(words, start, axis=1)
    assert v["TARGET_ANGLE"] == pytest.approx(12.5) and v["MODE"] == 2
    assert "TARGET_ANGLE[1]" in decode_block(words, start)
