"""What wire faults revealed in the Modbus drive links: a reply to another request is a
retried error (never a state), a client that lost its connection opens it again, the
devices of one line open its port together.  Faults are injected by the HIL on the wire
(the pty's serial handler, the TCP fault proxy), never by mocking the client."""

import asyncio

import pytest
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersResponse,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersResponse,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterResponse,
)

from controller.drives import DriveCommError, open_drive
from controller.drives.links import ModbusRtuLink, ModbusTcpLink
from controller.drives.modbus.client import ReplyMismatch, verify_reply
from hil.drive import DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil.serial_urls.protocol_ptyfd import WIRE_FAULTS
from hil.tcp_proxy import FaultProxy
from hil.wire_faults import WireFaults
from tests.conftest import two_axes


def run(coro):
    return asyncio.run(coro)


class Scripted:
    """A wire hook that does what it is told to the next replies: ``"stale"`` sends the
    previous reply instead (late for its request), then this one; a WireFaults kind damages
    it; None passes it."""

    def __init__(self):
        self.script: list[str | None] = []
        self.previous = b""
        self.faults = WireFaults(late_s=(0.35, 0.4))

    def rtu_reply(self, frame):
        kind = self.script.pop(0) if self.script else None
        previous, self.previous = self.previous, frame
        if kind == "stale":
            return [(0.0, previous), (0.05, frame)]
        return [(0.0, frame)] if kind is None else self.faults.apply_rtu(kind, frame)


@pytest.fixture
def faulty_line(sim_clock):
    """(firmware, pty path, wire hook): a two-axis drive, id 1, on a pty whose replies the
    hook may damage."""
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=30.0)
    hook = Scripted()
    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        WIRE_FAULTS[link.master_fd] = hook
        try:
            yield fw, link.path, hook
        finally:
            WIRE_FAULTS.pop(link.master_fd, None)


def test_a_late_reply_to_another_request_is_never_taken_as_the_state(faulty_line):
    fw, path, hook = faulty_line

    async def scenario():
        d = open_drive(ModbusRtuLink(name="rs485", port=path, timeout_s=0.3, retries=2), 1)
        await d.connect()
        try:
            await d.identify()  # a read of 14 registers
            hook.script = ["stale"]  # the state read first gets the identification's reply
            st = await d.read_state()
            assert [a.target_deg for a in st.axes] == pytest.approx([180.0, 90.0])
            assert d.stats.errors >= 1  # the mismatch was an error, and retried
        finally:
            await d.close()

    run(scenario())


@pytest.mark.parametrize(
    "kind", ["modbus_timeout", "crc_error", "garbled_reply", "split_reply", "late_reply", "wrong_id_reply"]
)
def test_every_rtu_wire_fault_is_retried_and_the_state_is_true(faulty_line, kind):
    fw, path, hook = faulty_line

    async def scenario():
        d = open_drive(ModbusRtuLink(name="rs485", port=path, timeout_s=0.3, retries=2), 1)
        await d.connect()
        try:
            hook.script = [kind]
            st = await d.exchange([150.0, 30.0])
            assert [a.target_deg for a in st.axes] == pytest.approx([150.0, 30.0])
            assert fw.axes[0].target == pytest.approx(150.0)
            if kind == "late_reply":  # its retry's reply comes late for the next request too
                assert 1 <= d.stats.errors <= 2
            else:
                assert d.stats.errors == (0 if kind == "split_reply" else 1)
        finally:
            await d.close()

    run(scenario())


def test_replies_are_checked_against_their_request():
    verify_reply("read_holding_registers", ReadHoldingRegistersResponse(registers=[1, 2]), (0,), {"count": 2})
    with pytest.raises(ReplyMismatch, match="function code 4"):
        verify_reply(
            "read_holding_registers", ReadInputRegistersResponse(registers=[1, 2]), (0,), {"count": 2}
        )
    with pytest.raises(ReplyMismatch, match="3 register"):
        verify_reply(
            "read_holding_registers", ReadHoldingRegistersResponse(registers=[1, 2, 3]), (0,), {"count": 2}
        )
    with pytest.raises(ReplyMismatch):
        verify_reply(
            "readwrite_registers", ReadWriteMultipleRegistersResponse(registers=[1]), (), {"read_count": 2}
        )
    verify_reply("write_registers", WriteMultipleRegistersResponse(address=20, count=2), (20, [1, 2]), {})
    with pytest.raises(ReplyMismatch):
        verify_reply("write_registers", WriteMultipleRegistersResponse(address=22, count=2), (20, [1, 2]), {})
    verify_reply("write_register", WriteSingleRegisterResponse(address=8, registers=[0]), (8, 1), {})
    with pytest.raises(ReplyMismatch):
        verify_reply("write_register", WriteSingleRegisterResponse(address=9, registers=[1]), (8, 1), {})


def test_the_drives_of_one_line_open_its_port_together(pty_drive):
    _fw, path, _ = pty_drive

    async def scenario():
        link = ModbusRtuLink(name="rs485", port=path, timeout_s=0.3, retries=0)
        drives = [open_drive(link, 1) for _ in range(3)]
        try:
            await asyncio.gather(*(d.connect() for d in drives))  # one port, opened once
            assert all(d.axis_count == 2 for d in drives)
        finally:
            for d in drives:
                await d.close()

    run(scenario())


def test_a_tcp_drive_reconnects_after_its_server_went_away(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=30.0)
    wire = WireFaults(tcp=True)
    with (
        ModbusServerThread({1: fw}, tcp=("127.0.0.1", 0)) as srv,
        FaultProxy(srv.tcp_port, wire) as proxy,
    ):

        async def scenario():
            link = ModbusTcpLink(name="gw", host="127.0.0.1", tcp_port=proxy.port, timeout_s=0.3, retries=1)
            d = open_drive(link, 1)
            await d.connect()
            try:
                await d.exchange([100.0, 20.0])
                proxy.set_down(1, True)  # the emulator process is killed: connection reset
                with pytest.raises(DriveCommError):
                    await d.read_state()
                proxy.set_down(1, False)  # and restarted
                st = await d.exchange([101.0, 21.0])  # no reconnect by the caller
                assert st.axes[0].target_deg == pytest.approx(101.0)
                wire.forced[1] = "garbled_reply"  # a header it cannot decode: the client drops
                with pytest.raises(DriveCommError):  # the connection, and opens it again
                    await d.read_state()
                del wire.forced[1]
                assert (await d.read_state()).axes[1].target_deg == pytest.approx(21.0)
            finally:
                await d.close()

        run(scenario())
