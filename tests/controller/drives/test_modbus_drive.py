"""The controller's Modbus client against the emulated firmware over a real pty."""

import pytest

from controller.drives import DriveCommError, open_drive
from firmware_protocol import Command, Mode, Status
from hil.drive import DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from tests.conftest import two_axes


@pytest.fixture
def drive(pty_drive):
    fw, path, clock = pty_drive
    d = open_drive("modbus-rtu", port=path, device_id=1, timeout_s=0.3, retries=1)
    d.connect()
    yield d, fw, clock
    d.close()


def test_connect_reads_identification(drive):
    d, fw, _ = drive
    assert d.axis_count == 2


def test_targets_state_and_configuration(drive):
    d, fw, clock = drive
    d.configure(heartbeat_timeout_s=50, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 80])
    assert fw.heartbeat_timeout == pytest.approx(50)
    assert fw.axes[1].p.soft_min == pytest.approx(5) and fw.axes[1].p.stow_angle == pytest.approx(80)
    d.write_targets([150.0, 30.0])
    for _ in range(8):
        d.heartbeat()
        clock.sleep(10)
    st = d.read_state()
    assert st.axes[0].actual_deg == pytest.approx(150.0, abs=0.03)
    assert st.axes[1].actual_deg == pytest.approx(30.0, abs=0.03)
    assert all(a.status & Status.AT_TARGET for a in st.axes)
    d.command(Command.STOW)
    assert d.read_state().axes[0].mode == Mode.STOW


def test_wrong_number_of_targets(drive):
    d, *_ = drive
    with pytest.raises(ValueError):
        d.write_targets([1.0])


def test_timeouts_become_drive_comm_errors_with_counts(pty_drive):
    fw, path, _ = pty_drive
    d = open_drive("modbus-rtu", port=path, device_id=5, timeout_s=0.05, retries=1)
    with pytest.raises(DriveCommError, match="id 5"):
        d.connect()
    assert d.stats.errors == 2 and d.stats.retries == 1
    d.close()


def test_not_a_heliotrack_drive(sim_clock):
    class Other:
        def read(self, a, n):
            return [0x1234] * n

        def write(self, a, v):
            pass

    with PtyLink.open() as link, ModbusServerThread({1: Other()}, serial_url=link.url):
        d = open_drive("modbus-rtu", port=link.path, device_id=1, timeout_s=0.3)
        with pytest.raises(DriveCommError, match="not a heliotrack drive"):
            d.connect()
        d.close()


def test_modbus_tcp_backend_on_loopback(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now)
    with ModbusServerThread({3: fw}, tcp=("127.0.0.1", 0)) as srv:
        d = open_drive("modbus-tcp", host="127.0.0.1", port=srv.tcp_port, device_id=3)
        d.connect()
        d.write_targets([181.0, 89.0])
        assert fw.axes[0].target == pytest.approx(181.0)
        d.close()


def test_unknown_backend():
    with pytest.raises(ValueError, match="known: .*modbus-rtu"):
        open_drive("profibus")
