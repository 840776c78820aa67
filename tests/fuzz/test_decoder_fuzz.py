"""Fuzzing the decoders of drive data (issue 13): the register codecs, the Modbus drive's
decoding of whatever a slave answers (any values, any number of registers, unknown modes
and faults) and the CANopen master's decoding of TPDO values.  The outcome is a value, a
ProtocolError (codec) or a DriveCommError (drive link); never another exception."""

from __future__ import annotations

import asyncio
import math
from types import SimpleNamespace

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from controller.drives.base import DriveCommError, DriveState
from controller.drives.canopen.axis import (
    IDX_EFFECTIVE_TARGET,
    IDX_FAULT,
    IDX_MODE,
    IDX_STATUS,
    Axis402,
)
from controller.drives.modbus.drive import ModbusDrive
from firmware_protocol import MAGIC, PROTOCOL_VERSION, REGISTER_MAP, ProtocolError, decode, encode
from firmware_protocol.codec import decode_axis, decode_block, words_to_raw
from firmware_protocol.registers import REGISTER_SPACE

from .strategies import bounded

registers = st.sampled_from(REGISTER_MAP)
words16 = st.integers(0, 0xFFFF)
any_words = st.one_of(words16, st.integers(-(2**20), 2**20), st.sampled_from([-1, 0x10000, 2**40]))


@bounded(300)
@given(registers, st.lists(any_words, max_size=3))
def test_codec_decodes_any_words_or_says_why(reg, words):
    try:
        v = decode(reg, words)
    except ProtocolError:
        assert len(words) != reg.words or any(not 0 <= w <= 0xFFFF for w in words)
        return
    assert math.isfinite(v) and v == words_to_raw(reg, words) * reg.scale
    assert encode(reg, v) == list(words)  # and back to the same words


@bounded(300)
@given(registers, st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-(2**40), 2**40)))
@example(register := REGISTER_MAP[0], float("nan"))
def test_codec_encodes_any_number_or_says_why(reg, value):
    try:
        words = encode(reg, value)
    except ProtocolError:
        return
    assert len(words) == reg.words and all(0 <= w <= 0xFFFF for w in words)
    assert abs(decode(reg, words) - value) <= reg.scale / 2 + 1e-9 * abs(value)


@bounded(200)
@given(st.lists(words16, max_size=80), st.integers(0, REGISTER_SPACE), st.sampled_from([None, 0, 1]))
def test_block_decoders_take_any_slice(words, start, axis):
    out = decode_block(words, start, axis)
    assert all(math.isfinite(v) for v in out.values())
    try:
        decode_axis(words, start % (len(words) + 1))
    except ProtocolError:
        pass


# -- the Modbus drive link against a slave that answers anything --------------------------------
class AnySlave:
    """A pymodbus client stand-in whose answers are drawn by hypothesis."""

    def __init__(self, answers):
        self.answers = answers

    async def connect(self) -> bool:
        return True

    def close(self) -> None:
        pass

    def _answer(self, count: int | None = None):
        regs = self.answers.draw(
            st.one_of(
                st.lists(words16, min_size=count or 0, max_size=count or 0) if count else st.nothing(),
                st.lists(words16, max_size=40),
            )
        )
        return SimpleNamespace(registers=regs, isError=lambda: False)

    async def read_holding_registers(self, address, count=1, device_id=1):
        # identification answers are plausible most of the time, so the rest is reached
        if address == 0 and self.answers.draw(st.booleans()):
            regs = [MAGIC, PROTOCOL_VERSION, self.answers.draw(st.sampled_from([1, 2]))]
            regs += self.answers.draw(st.lists(words16, min_size=count, max_size=count))
            return SimpleNamespace(registers=regs[:count], isError=lambda: False)
        return self._answer(count)

    async def readwrite_registers(self, read_address, read_count, write_address, values, device_id=1):
        return self._answer(read_count)

    async def write_registers(self, address, values, device_id=1):
        return SimpleNamespace(registers=[], isError=lambda: False)

    async def write_register(self, address, value, device_id=1):
        return SimpleNamespace(registers=[], isError=lambda: False)


async def _session(drive: ModbusDrive) -> None:
    await drive.connect()
    state = await drive.read_state()
    assert isinstance(state, DriveState) and len(state.axes) == drive.axis_count
    for a in state.axes:
        assert math.isfinite(a.actual_deg) and math.isfinite(a.target_deg)
    await drive.exchange([10.0] * drive.axis_count)
    await drive.identify()
    await drive.read_register("STOW_ANGLE", 0)
    await drive.configure(soft_limits=[(0.0, 90.0)] * drive.axis_count, stow_angles=[45.0] * drive.axis_count)


@bounded(200)
@given(st.data())
def test_a_modbus_drive_decodes_whatever_its_slave_answers(data):
    drive = ModbusDrive(AnySlave(data), 1, retries=0, label="fuzz")
    try:
        asyncio.run(_session(drive))
    except DriveCommError:
        pass


# -- CANopen TPDO values -------------------------------------------------------------------
tpdo_values = st.fixed_dictionaries(
    {},
    optional={
        0x6041: st.integers(0, 0xFFFF),
        0x6064: st.integers(-(2**31), 2**31 - 1),
        0x606C: st.integers(-(2**31), 2**31 - 1),
        IDX_EFFECTIVE_TARGET: st.integers(-(2**31), 2**31 - 1),
        IDX_STATUS: st.one_of(st.integers(0, 0xFFFF), st.integers(-(2**40), 2**40)),
        IDX_FAULT: st.one_of(st.integers(0, 0xFFFF), st.integers(-5, 5)),
        IDX_MODE: st.one_of(st.integers(0, 0xFFFF), st.integers(-5, 5)),
    },
)


@bounded(300)
@given(tpdo_values)
def test_canopen_tpdo_values_decode_or_are_refused(values):
    axis = Axis402(SimpleNamespace(id=5, tpdo_values=values))
    try:
        st_ = axis.axis_state("fuzz")
    except DriveCommError:
        return
    assert math.isfinite(st_.actual_deg) and math.isfinite(st_.velocity_dps)
    _ = axis.state  # any statusword maps to a 402 state or None


@pytest.mark.parametrize("n", [0, 1, 13])
def test_a_short_state_answer_is_a_comm_error(n):
    drive = ModbusDrive(None, 1, label="fuzz")
    drive.axis_count = 1
    with pytest.raises(DriveCommError):
        drive._decode_state([0] * n)
