"""The controller's Modbus client against the emulated firmware over a real pty."""

import asyncio

import pytest

from controller.clock import SimClock
from controller.drives import DriveCommError, open_drive
from controller.drives.links import ModbusRtuLink, ModbusTcpLink
from firmware_protocol import Command, Mode, Status, register
from hil.drive import DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from tests.conftest import two_axes


def run(coro):
    return asyncio.run(coro)


def rtu(path: str, **kw) -> ModbusRtuLink:
    return ModbusRtuLink(name="rs485", port=path, **kw)


def test_connect_targets_state_and_configuration(pty_drive):
    fw, path, clock = pty_drive

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        assert d.axis_count == 2
        await d.configure(heartbeat_timeout_s=50, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 80])
        assert fw.heartbeat_timeout == pytest.approx(50)
        assert fw.axes[1].p.soft_min == pytest.approx(5) and fw.axes[1].p.stow_angle == pytest.approx(80)
        await d.write_targets([150.0, 30.0])
        for _ in range(8):
            await d.heartbeat()
            clock.sleep(10)
        st = await d.read_state()
        assert st.axes[0].actual_deg == pytest.approx(150.0, abs=0.03)
        assert st.axes[1].actual_deg == pytest.approx(30.0, abs=0.03)
        assert all(a.status & Status.AT_TARGET for a in st.axes)
        # exchange = targets + state in fewer transactions; the state is read after the write
        st = await d.exchange([151.0, 31.0])
        assert st.axes[0].target_deg == pytest.approx(151.0)
        assert st.axes[1].target_deg == pytest.approx(31.0)
        await d.command(Command.STOW)
        assert (await d.read_state()).axes[0].mode == Mode.STOW
        with pytest.raises(ValueError):
            await d.write_targets([1.0])
        await d.close()

    run(scenario())


def test_the_configuration_read_has_each_axis_speed_limit(sim_clock):
    """``check`` prints the speed limit each drive holds (docs/deploy.md's example): a
    Modbus drive's read-back had none, only a CANopen drive's did."""
    fw = DriveFirmware(two_axes(max_speed=2.5), sim_clock.now, heartbeat_timeout=30.0)
    fw.axes[1].p.max_speed = 4.0

    async def scenario(path):
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        got = await d.read_configuration()
        await d.close()
        assert got.max_speeds == (2.5, 4.0)
        assert got.stow_angles == (180.0, 90.0)
        assert "speed 2.5 / 4 deg/s" in got.describe()

    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        run(scenario(link.path))


def test_timeouts_become_drive_comm_errors_with_counts(pty_drive):
    _fw, path, _ = pty_drive

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.05, retries=1), 5)
        with pytest.raises(DriveCommError, match="id 5"):
            await d.connect()
        assert d.stats.errors == 2 and d.stats.retries == 1
        await d.close()

    run(scenario())


def test_not_a_heliotrack_drive():
    class Other:
        def read(self, a, n):
            return [0x1234] * n

        def write(self, a, v):
            pass

    async def scenario(path):
        d = open_drive(rtu(path, timeout_s=0.3), 1)
        with pytest.raises(DriveCommError, match="not a heliotrack drive"):
            await d.connect()
        await d.close()

    with PtyLink.open() as link, ModbusServerThread({1: Other()}, serial_url=link.url):
        run(scenario(link.path))


def test_implausible_state_is_an_error_not_a_crash(pty_drive):
    fw, path, _ = pty_drive
    fw.modes[0] = 7  # a firmware bug puts an unknown mode on the wire

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.3, retries=0), 1)
        await d.connect()
        with pytest.raises(DriveCommError, match="implausible"):
            await d.read_state()
        await d.close()

    run(scenario())


def test_modbus_tcp_backend_on_loopback(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now)

    async def scenario(port):
        d = open_drive(ModbusTcpLink(name="tcp", host="127.0.0.1", tcp_port=port), 3)
        await d.connect()
        st = await d.exchange([181.0, 89.0])
        assert fw.axes[0].target == pytest.approx(181.0)
        assert st.axes[1].target_deg == pytest.approx(89.0)
        await d.close()

    with ModbusServerThread({3: fw}, tcp=("127.0.0.1", 0)) as srv:
        run(scenario(srv.tcp_port))


def test_a_configuration_the_drive_does_not_take_is_refused(pty_drive):
    """An audit's case: a firmware that acknowledged the writes and kept its watchdog off
    and its factory limits was driven as configured, reported ok."""
    from firmware_protocol import register

    fw, path, clock = pty_drive
    ignored = {
        register("HEARTBEAT_TIMEOUT").address(),
        register("SOFT_LIMIT_MIN").address(1),
        register("STOW_ANGLE").address(1),
    }
    write = fw.write
    fw.write = lambda address, words: None if address in ignored else write(address, words)

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        try:
            await d.configure(heartbeat_timeout_s=50, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 80])
        finally:
            await d.close()

    with pytest.raises(DriveCommError) as e:
        run(scenario())
    msg = str(e.value)
    assert "configuration not taken: watchdog reads" in msg and "50 s written" in msg
    assert "axis 1 soft limits read" in msg and "[5, 85] written" in msg
    assert "axis 1 stow angle reads" in msg and "80 written" in msg


async def connected(path: str):
    """Drive 1 on the pty, connected (0.3-s timeout, one retry)."""
    d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
    await d.connect()
    return d


def another_magic(read):
    """``read`` as a drive that answers the identification with MAGIC 0xBEEF."""

    def other_device(address, count):
        words = read(address, count)
        return [0xBEEF, *words[1:]] if address == 0 else words

    return other_device


def test_an_identity_that_changes_after_connect_is_an_error(pty_drive):
    """An audit's case: every other identification read said MAGIC 0xBEEF, protocol 7, one
    axis; run went on, 0 errors."""
    fw, path, clock = pty_drive
    read = fw.read
    other_device = another_magic(read)

    async def scenario():
        d = await connected(path)
        await d.identify()  # the drive it connected to
        fw.read = other_device
        try:
            await d.identify()
        finally:
            await d.close()

    with pytest.raises(DriveCommError, match=r"identity changed \(register 0 = 0xbeef"):
        run(scenario())


@pytest.fixture
def no_fc23(pty_drive, monkeypatch):
    """The pty drive as a firmware implementing FC 3, 6 and 16 only: (firmware, pty path)."""
    import hil.modbus_device

    monkeypatch.setattr(hil.modbus_device, "_REGISTER_FCS", {3, 6, 16})
    return pty_drive[0], pty_drive[1]


def test_a_drive_without_fc23_is_driven_by_fc16_and_fc3(no_fc23, caplog):
    """A firmware-side audit's case: a drive implementing FC 3, 6 and 16 (all the register
    map then listed) was refused every cycle with exception 1 after connecting fine."""
    fw, path = no_fc23

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        try:
            first = await d.exchange([150.0, 30.0])
            second = await d.exchange([151.0, 31.0])
            return first, second, d.fc23
        finally:
            await d.close()

    first, second, fc23 = run(scenario())
    assert not fc23
    assert first.axes[0].target_deg == pytest.approx(150.0) and second.axes[1].target_deg == pytest.approx(
        31.0
    )
    assert fw.axes[0].target == pytest.approx(151.0)
    warned = [r for r in caplog.records if "no FC 23" in r.getMessage()]
    assert len(warned) == 1


def test_a_tcp_endpoint_where_nothing_listens_says_so():
    """An audit's case: the row said only "cannot open the link" (pymodbus logs the reason
    on a line of its own and keeps none)."""
    import socket

    with socket.socket() as s:  # a port just free: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]

    async def scenario():
        d = open_drive(ModbusTcpLink(name="lan", host="127.0.0.1", tcp_port=port, timeout_s=0.5), 2)
        with pytest.raises(DriveCommError) as e:
            await d.connect()
        return str(e.value)

    msg = run(scenario())
    assert f"cannot open the link: 127.0.0.1:{port}: connection refused (nothing listens there" in msg, msg


def test_the_heartbeat_and_the_identification_read_are_one_transaction(pty_drive):
    """HEARTBEAT (register 9) lies inside the identification block (0-13): one FC 23 writes
    the heartbeat and reads the identity back.  The identification read after every
    heartbeat, as a transaction of its own, had cost every drive one more transaction a
    cycle with the default watchdog (the 5-day loop benchmark: 36010 -> 50420)."""
    fw, path, clock = pty_drive
    read = fw.read
    other_device = another_magic(read)

    async def scenario():
        d = await connected(path)
        try:
            beats, uptimes = [], []
            before = d.stats.transactions
            for _ in range(3):
                ident = await d.heartbeat_identify()
                beats.append(fw.heartbeat)
                uptimes.append(ident.uptime_s)
                clock.sleep(10)
            rounds = d.stats.transactions - before
            assert (ident.axis_count, d.fc23, d.fc23_heartbeat) == (2, True, True)
            fw.read = other_device  # the identity is still checked every round
            with pytest.raises(DriveCommError, match=r"identity changed \(register 0 = 0xbeef"):
                await d.heartbeat_identify()
            return beats, uptimes, rounds
        finally:
            fw.read = read
            await d.close()

    beats, uptimes, rounds = run(scenario())
    assert rounds == 3
    assert len(set(beats)) == 3  # each round a new heartbeat: the watchdog is fed
    assert uptimes[1] - uptimes[0] == pytest.approx(10, abs=1) and uptimes[2] > uptimes[1]


def test_a_drive_without_fc23_gets_its_heartbeat_and_identification_by_fc6_and_fc3(no_fc23, caplog):
    fw, path = no_fc23

    async def scenario():
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        try:
            first = await d.heartbeat_identify()
            beat = fw.heartbeat
            before = d.stats.transactions
            second = await d.heartbeat_identify()
            await d.exchange([150.0, 30.0])
            return first, second, beat, d.stats.transactions - before, d.fc23
        finally:
            await d.close()

    first, second, beat, used, fc23 = run(scenario())
    assert not fc23 and first.axis_count == second.axis_count == 2
    assert fw.heartbeat != beat and fw.heartbeat != 0
    assert used == 2 + 3  # heartbeat + identification, then two targets + the state
    assert len([r for r in caplog.records if "no FC 23" in r.getMessage()]) == 1


def test_a_drive_whose_fc23_takes_only_the_exchange_gets_fc6_and_fc3_for_the_heartbeat(monkeypatch, caplog):
    """A firmware whose FC 23 refuses anything but the exchange (exception 2) is still fed
    its heartbeat and identified, and keeps its FC 23 exchange."""
    from pymodbus.constants import ExcCodes
    from pymodbus.simulator import SimDevice

    import hil.modbus_server

    real = hil.modbus_server.sim_device
    heartbeat = register("HEARTBEAT").address()

    def narrow_fc23(device_id, device, *args):
        sim = real(device_id, device, *args)

        async def action(fc, start, address, count, registers, set_values):
            if fc == 23 and set_values is not None and address == heartbeat:
                return ExcCodes.ILLEGAL_ADDRESS
            return await sim.action(fc, start, address, count, registers, set_values)

        return SimDevice(id=sim.id, simdata=sim.simdata, action=action)

    monkeypatch.setattr(hil.modbus_server, "sim_device", narrow_fc23)
    clock = SimClock(1_710_900_000.0)
    fw = DriveFirmware(two_axes(), clock.now, heartbeat_timeout=30.0)

    async def scenario(path):
        d = open_drive(rtu(path, timeout_s=0.3, retries=1), 1)
        await d.connect()
        try:
            ident = await d.heartbeat_identify()
            beat = fw.heartbeat
            await d.heartbeat_identify()
            st = await d.exchange([150.0, 30.0])
            return ident, beat, st, d.fc23, d.fc23_heartbeat
        finally:
            await d.close()

    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        ident, beat, st, fc23, fc23_heartbeat = run(scenario(link.path))
    assert ident.axis_count == 2 and fw.heartbeat not in (0, beat)
    assert fc23 and not fc23_heartbeat and st.axes[1].target_deg == pytest.approx(30.0)
    assert len([r for r in caplog.records if "FC 23 refused for the heartbeat" in r.getMessage()]) == 1
