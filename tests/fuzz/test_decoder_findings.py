"""What the decoder fuzzers found (issue 13), one regression test each."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace

import pytest

from controller.drives.base import DriveCommError
from controller.drives.modbus.drive import ModbusDrive
from firmware_protocol import MAGIC, PROTOCOL_VERSION, ProtocolError, encode


class ShortSlave:
    """Answers every read with ``short`` registers fewer than asked (a slave may send any
    byte count; pymodbus passes it on)."""

    def __init__(self, short: int = 1, identify_ok: bool = False):
        self.short, self.identify_ok, self.reads = short, identify_ok, 0

    async def connect(self):
        return True

    def close(self):
        pass

    def _answer(self, count):
        self.reads += 1
        return SimpleNamespace(registers=[0] * max(count - self.short, 0), isError=lambda: False)

    async def read_holding_registers(self, address, count=1, device_id=1):
        if address == 0 and count == 3 and self.identify_ok:
            return SimpleNamespace(registers=[MAGIC, PROTOCOL_VERSION, 2], isError=lambda: False)
        return self._answer(count)

    async def readwrite_registers(self, read_address, read_count, write_address, values, device_id=1):
        return self._answer(read_count)

    async def write_registers(self, address, values, device_id=1):
        return SimpleNamespace(registers=[], isError=lambda: False)


def test_a_short_identification_answer_is_a_comm_error_not_an_index_error():
    slave = ShortSlave()
    drive = ModbusDrive(slave, 4, retries=2, label="id 4")
    with pytest.raises(
        DriveCommError, match=r"id 4: identification read failed after 3 attempt\(s\): .*2 register"
    ):
        asyncio.run(drive.connect())
    assert slave.reads == 3  # retried like a garbled frame


@pytest.mark.parametrize("call", ["identify", "soft limits", "register", "state", "exchange"])
def test_every_read_refuses_a_short_answer(call):
    """identify(), the soft-limit read of configure() and read_register() raised
    ProtocolError (a ValueError) out of the codec: a bug to the loop, not a link failure.
    (The state reads already refused an answer lacking words they decode; now every read
    refuses an answer shorter than asked, and retries it.)"""

    async def run():
        drive = ModbusDrive(ShortSlave(identify_ok=True), 4, retries=0, label="id 4")
        await drive.connect()
        if call == "identify":
            await drive.identify()
        elif call == "soft limits":
            await drive.configure(soft_limits=[(0.0, 360.0), (0.0, 90.0)], stow_angles=[180.0, 90.0])
        elif call == "register":
            await drive.read_register("STOW_ANGLE", 1)
        elif call == "state":
            await drive.read_state()
        else:
            await drive.exchange([180.0, 45.0])

    with pytest.raises(DriveCommError, match="register.* in the answer"):
        asyncio.run(run())


def test_encoding_a_huge_finite_value_is_a_protocol_error():
    # round(1e307 / 0.1) raised OverflowError
    with pytest.raises(ProtocolError, match="far outside"):
        encode("HEARTBEAT_TIMEOUT", 1.7e308)
    with pytest.raises(ProtocolError, match="far outside"):
        encode("TARGET_ANGLE", 1e306)


def test_a_fraction_is_not_truncated_into_an_unscaled_register():
    # int(1.5) wrote MODE 1 (STOW), int(2.9) COMMAND 2 (RESUME)
    with pytest.raises(ProtocolError, match="whole number"):
        encode("MODE", 1.5)
    with pytest.raises(ProtocolError, match="whole number"):
        encode("COMMAND", 2.9)
    assert encode("MODE", 2.0) == [2]


def test_a_garbled_sdo_answer_is_a_comm_error_not_an_object_dictionary_error():
    """A node answering an SDO upload with fewer bytes than the object's type: canopen's
    decode raised ObjectDictionaryError, which the retry policy let through, out of
    CanopenDrive.connect() and so out of Controller.start() (only DriveCommError and
    timeouts are a drive's failure there)."""
    import threading
    import uuid

    import can

    from controller.drives.canopen.drive import CanopenDrive

    channel = f"ht-garbled-{uuid.uuid4().hex[:8]}"
    rogue = can.Bus(interface="virtual", channel=channel)
    stop = threading.Event()
    uploads = []

    def answer() -> None:
        while not stop.is_set():
            msg = rogue.recv(0.02)
            if msg is not None and msg.arbitration_id == 0x605 and msg.data[0] & 0xE0 == 0x40:
                uploads.append(bytes(msg.data[1:4]))
                # expedited upload response with 1 byte for an UNSIGNED16 object
                data = bytes([0x4F]) + bytes(msg.data[1:4]) + b"\x48\x00\x00\x00"
                rogue.send(can.Message(arbitration_id=0x585, data=data, is_extended_id=False))

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()
    drive = CanopenDrive(5, channel=channel, interface="virtual", timeout_s=0.3, retries=1, label="node 5")
    try:
        with pytest.raises(DriveCommError, match="node 5: identification read failed after 2 attempt"):
            asyncio.run(drive.connect())
        assert len(uploads) == 2  # retried like a garbled frame
    finally:
        stop.set()
        thread.join(1.0)
        rogue.shutdown()
