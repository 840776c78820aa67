"""Clients of Modbus links: line settings reach the port, one client per line, and what an
exception response means for a retry."""

import asyncio
import os
import termios

import pytest

from controller.drives import DriveCommError, LinkSettingsError, open_drive
from controller.drives.links import ModbusRtuLink, ModbusTcpLink
from controller.drives.modbus.client import SharedSerialClient, modbus_client
from controller.sensors.pyranometer import ModbusPyranometer
from hil.drive import DriveFirmware
from hil.drive.firmware import FirmwareReject
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil.pyranometer import Pyranometer
from tests.conftest import two_axes


def run(coro):
    return asyncio.run(coro)


def test_baudrate_and_stop_bits_reach_the_serial_port(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now)
    with PtyLink.open() as pty, ModbusServerThread({1: fw}, serial_url=pty.url):
        before = termios.tcgetattr(pty.slave_fd)
        assert before[4] != termios.B19200 and not before[2] & termios.CSTOPB

        async def scenario():
            d = open_drive(ModbusRtuLink(name="rs485", port=pty.path, baudrate=19200, stopbits=2), 1)
            await d.connect()
            try:
                # The kernel's view of the line: what the client asked the port for.
                attrs = termios.tcgetattr(pty.slave_fd)
                assert attrs[4] == attrs[5] == termios.B19200
                assert attrs[2] & termios.CSTOPB and not attrs[2] & termios.PARENB
                assert (await d.exchange([10.0, 20.0])).axes[1].target_deg == pytest.approx(20.0)
            finally:
                await d.close()

        run(scenario())


def test_parity_reaches_the_serial_client(sim_clock):
    # Linux refuses a parity bit on a pty, so the slave end is opened through the
    # emulator's ptyfd:// handler: pyserial itself holds the link's settings.
    fw = DriveFirmware(two_axes(), sim_clock.now)
    with PtyLink.open() as pty, ModbusServerThread({1: fw}, serial_url=pty.url, parity="O"):

        async def scenario():
            d = open_drive(
                ModbusRtuLink(name="rs485", port=pty.slave_url, baudrate=9600, parity="O", stopbits=2), 1
            )
            await d.connect()
            try:
                port = d.client.client.ctx.transport.sync_serial
                assert (port.baudrate, port.parity, port.stopbits, port.bytesize) == (9600, "O", 2, 8)
                await d.exchange([15.0, 25.0])
                assert fw.axes[0].target == pytest.approx(15.0)
            finally:
                await d.close()

        run(scenario())


def test_devices_on_one_line_share_one_client_until_the_last_closes():
    async def scenario():
        link = ModbusRtuLink(name="rs485", port="/dev/ttyFAKE0")
        a, b = open_drive(link, 1), open_drive(link, 2)
        pyr = ModbusPyranometer.from_config(link, 10)
        assert a.client is b.client is pyr.client
        assert a.client.users == 3
        await a.close()
        await a.close()  # closing twice releases once
        await pyr.close()
        assert SharedSerialClient._open.get("/dev/ttyFAKE0") is b.client
        await b.close()
        assert "/dev/ttyFAKE0" not in SharedSerialClient._open

    run(scenario())


@pytest.mark.parametrize("other", [{"baudrate": 9600}, {"parity": "E"}, {"stopbits": 2}, {"timeout_s": 1.0}])
def test_two_links_on_one_port_with_different_settings_are_refused(other):
    async def scenario():
        first = open_drive(ModbusRtuLink(name="line-a", port="/dev/ttyFAKE1"), 1)
        try:
            with pytest.raises(LinkSettingsError) as err:
                open_drive(ModbusRtuLink(name="line-b", port="/dev/ttyFAKE1", **other), 2)
            msg = str(err.value)
            assert "'line-a'" in msg and "'line-b'" in msg and "/dev/ttyFAKE1" in msg
            # The same settings under another link name share the line.
            same = open_drive(ModbusRtuLink(name="line-c", port="/dev/ttyFAKE1"), 3)
            assert same.client is first.client
            await same.close()
        finally:
            await first.close()

    run(scenario())


def test_simulator_only_addresses_are_refused_outside_simulate():
    async def scenario():
        with pytest.raises(LinkSettingsError, match='port = "hil"'):
            open_drive(ModbusRtuLink(name="rs485"), 1)
        with pytest.raises(LinkSettingsError, match='host = "hil"'):
            modbus_client(ModbusTcpLink(name="tcp"))

    run(scenario())


class _Refusing:
    """A device that answers every request with an exception response."""

    def __init__(self, code: int, times: int = 10**9):
        self.code, self.left, self.requests = code, times, 0
        self.fw = DriveFirmware(two_axes(), lambda: 0.0)

    def read(self, address, count):
        self.requests += 1
        if self.left > 0:
            self.left -= 1
            raise FirmwareReject(self.code, "test")
        return self.fw.read(address, count)

    def write(self, address, values):
        self.fw.write(address, values)


def test_an_exception_response_is_final_not_retried():
    dev = _Refusing(code=2)

    async def scenario(port):
        d = open_drive(ModbusTcpLink(name="tcp", host="127.0.0.1", tcp_port=port, retries=2), 1)
        with pytest.raises(DriveCommError, match="refused by the drive: exception 2"):
            await d.connect()
        assert (d.stats.transactions, d.stats.errors, d.stats.retries) == (1, 1, 0)
        await d.close()

    with ModbusServerThread({1: dev}, tcp=("127.0.0.1", 0)) as srv:
        run(scenario(srv.tcp_port))
    assert dev.requests == 1


def test_a_busy_device_is_retried():
    dev = _Refusing(code=6, times=1)  # SERVER DEVICE BUSY once, then answers

    async def scenario(port):
        d = open_drive(ModbusTcpLink(name="tcp", host="127.0.0.1", tcp_port=port, retries=1), 1)
        await d.connect()
        assert d.axis_count == 2
        assert (d.stats.transactions, d.stats.errors, d.stats.retries) == (2, 1, 1)
        await d.close()

    with ModbusServerThread({1: dev}, tcp=("127.0.0.1", 0)) as srv:
        run(scenario(srv.tcp_port))


def test_pyranometer_on_modbus_tcp_connects_by_itself(sim_clock):
    sensor = Pyranometer(lambda t: 500.0, sim_clock.now, noise_w_m2=0.0)

    async def scenario(port):
        pyr = ModbusPyranometer.from_config(ModbusTcpLink(name="tcp", host="127.0.0.1", tcp_port=port), 10)
        sample = await pyr.read(123.0)  # no connect() first: read opens the link
        assert (sample.time, sample.ghi_w_m2) == (123.0, pytest.approx(500.0, abs=1))
        await pyr.close()

    with ModbusServerThread({10: sensor}, tcp=("127.0.0.1", 0)) as srv:
        run(scenario(srv.tcp_port))


def test_a_drive_closed_and_connected_again_rejoins_its_lines_client(sim_clock):
    fws = {i: DriveFirmware(two_axes(), sim_clock.now) for i in (1, 2)}
    with PtyLink.open() as pty, ModbusServerThread(fws, serial_url=pty.url):

        async def scenario():
            link = ModbusRtuLink(name="rs485", port=pty.path)
            a, b = open_drive(link, 1), open_drive(link, 2)
            await a.connect()
            await b.connect()
            await a.close()  # as the loop does before reconnecting
            await a.connect()
            try:
                assert a.client is b.client and a.client.users == 2  # one client per line
                await a.exchange([11.0, 12.0])
                await b.exchange([21.0, 22.0])
                assert (fws[1].axes[0].target, fws[2].axes[0].target) == (11.0, 21.0)
            finally:
                await a.close()
                await b.close()
            assert pty.path not in SharedSerialClient._open

        run(scenario())


def test_a_port_that_refuses_its_line_settings_is_named_and_left_free(sim_clock):
    """An audit's case: Linux refuses a parity bit on a pty with ``termios.error`` (no
    OSError), which went through check's and run's handlers as a traceback; and the
    transport pymodbus had half made kept the port locked."""
    fw = DriveFirmware(two_axes(), sim_clock.now)
    with PtyLink.open() as pty, ModbusServerThread({1: fw}, serial_url=pty.url):

        async def scenario():
            d = open_drive(ModbusRtuLink(name="rs485", port=pty.path, parity="E"), 1)
            with pytest.raises(DriveCommError) as e:
                await d.connect()
            await d.close()
            assert str(e.value) == (
                f"{pty.path}: cannot configure the port (baudrate 115200, parity E, stopbits 1): "
                "Invalid argument"
            )
            ok = open_drive(ModbusRtuLink(name="rs485", port=pty.path), 1)  # the port is free again
            await ok.connect()
            await ok.close()

        run(scenario())


@pytest.mark.parametrize("case", ["missing", "not a tty", "in use", "a folder"])
def test_a_port_that_does_not_open_says_why(tmp_path, case):
    """An audit's case: every one of these was "cannot open the link", the reason dropped
    (pymodbus catches pyserial's exception and returns False)."""
    import serial

    with PtyLink.open() as pty:
        port, holder = str(tmp_path / "ttyUSB9"), None
        if case == "not a tty":
            (tmp_path / "ttyUSB9").write_text("")
        elif case == "a folder":
            port = str(tmp_path)
        elif case == "in use":  # another master holds the port (pymodbus and pyserial lock it)
            port = pty.path
            holder = serial.Serial(pty.path, exclusive=True)

        async def scenario():
            d = open_drive(ModbusRtuLink(name="rs485", port=port, timeout_s=0.1, retries=0), 1)
            try:
                with pytest.raises(DriveCommError) as e:
                    await d.connect()
            finally:
                await d.close()
            return str(e.value)

        try:
            said = run(scenario())
        finally:
            if holder is not None:
                holder.close()
    expected = {
        "missing": f"{port}: no such device (unplugged, or another name: see /dev/serial/by-id/)",
        "not a tty": f"{port}: not a serial port (not a tty)",
        "in use": f"{port}: in use by another program (is heliotrack run active?)",
        "a folder": f"{port}: cannot open the port: Is a directory",
    }[case]
    assert said == expected


@pytest.mark.skipif(os.geteuid() == 0, reason="root opens any file: no EACCES to see")
def test_a_port_this_user_may_not_open_names_the_dialout_group(tmp_path):
    port = tmp_path / "ttyUSB0"
    port.write_text("")
    port.chmod(0)

    async def scenario():
        d = open_drive(ModbusRtuLink(name="rs485", port=str(port), timeout_s=0.1, retries=0), 1)
        try:
            with pytest.raises(
                DriveCommError, match=r"permission denied \(is the user in the dialout group\?\)"
            ):
                await d.connect()
        finally:
            await d.close()

    run(scenario())


def test_the_reasons_a_port_does_not_open_in_the_users_words():
    """What pyserial raises for each (the cases a test run as root cannot produce)."""
    import errno

    import serial

    from controller.drives.modbus.client import port_error

    tty = "/dev/ttyUSB0"
    denied = serial.SerialException(errno.EACCES, f"could not open port {tty}: [Errno 13] Permission denied")
    assert port_error(tty, denied) == f"{tty}: permission denied (is the user in the dialout group?)"
    busy = serial.SerialException(
        errno.EBUSY, f"could not open port {tty}: [Errno 16] Device or resource busy"
    )
    assert port_error(tty, busy) == f"{tty}: in use by another program (is heliotrack run active?)"
    gone = serial.SerialException(
        errno.ENXIO, f"could not open port {tty}: [Errno 6] No such device or address"
    )
    assert port_error(tty, gone) == f"{tty}: no such device (unplugged?)"
