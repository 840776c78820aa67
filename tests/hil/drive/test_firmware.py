import pytest

from firmware_protocol import MAGIC, Command, Fault, Mode, Status, decode, encode, register
from hil.drive import DriveFirmware, FirmwareReject
from tests.conftest import two_axes


def addr(name, axis=None):
    return register(name).address(axis)


def read(fw, name, axis=None):
    reg = register(name)
    return decode(reg, fw.read(reg.address(axis), reg.words))


def write(fw, name, value, axis=None):
    fw.write(addr(name, axis), encode(name, value))


@pytest.fixture
def fw(sim_clock):
    return DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=10.0)


def test_identification(fw):
    assert fw.read(0, 3) == [MAGIC, 0x0100, 2]


def test_target_is_reached_on_the_clock(fw, sim_clock):
    write(fw, "TARGET_ANGLE", 170.0, 0)
    sim_clock.sleep(1.0)
    assert Status(read(fw, "STATUS", 0)) & Status.MOVING
    for beat in range(1, 15):
        write(fw, "HEARTBEAT", beat)
        sim_clock.sleep(1.0)
    assert read(fw, "ACTUAL_ANGLE", 0) == pytest.approx(170.0, abs=0.03)
    assert Status(read(fw, "STATUS", 0)) & Status.AT_TARGET


def test_out_of_limit_target_is_clamped_and_flagged(fw, sim_clock):
    write(fw, "TARGET_ANGLE", 120.0, 1)
    assert read(fw, "TARGET_ANGLE", 1) == pytest.approx(90.0)
    assert Status(read(fw, "STATUS", 1)) & Status.TARGET_CLAMPED
    write(fw, "TARGET_ANGLE", 80.0, 1)
    assert not Status(read(fw, "STATUS", 1)) & Status.TARGET_CLAMPED


def test_watchdog_stows_when_heartbeat_stops(fw, sim_clock):
    write(fw, "TARGET_ANGLE", 100.0, 0)
    for beat in range(1, 12):  # alive for 11 s
        write(fw, "HEARTBEAT", beat)
        sim_clock.sleep(1.0)
    assert not Status(read(fw, "DEVICE_STATUS")) & Status.COMM_LOST
    sim_clock.sleep(10.5)  # silence longer than the timeout
    status = Status(read(fw, "STATUS", 0))
    assert status & Status.COMM_LOST
    assert read(fw, "MODE", 0) == Mode.STOW
    sim_clock.sleep(200)
    assert read(fw, "ACTUAL_ANGLE", 0) == pytest.approx(180.0, abs=0.03)
    assert Status(read(fw, "STATUS", 0)) & Status.STOWED
    # Targets are ignored while stowed; heartbeat + RESUME returns to AUTO.
    write(fw, "TARGET_ANGLE", 100.0, 0)
    assert read(fw, "TARGET_ANGLE", 0) == pytest.approx(180.0)
    write(fw, "HEARTBEAT", 99)
    write(fw, "COMMAND", Command.RESUME)
    assert read(fw, "MODE", 0) == Mode.AUTO
    assert not Status(read(fw, "STATUS", 0)) & Status.COMM_LOST


def test_watchdog_disabled_with_zero_timeout_in_maintenance(fw, sim_clock):
    write(fw, "MODE", Mode.MAINTENANCE, 0)
    write(fw, "MODE", Mode.MAINTENANCE, 1)
    write(fw, "HEARTBEAT_TIMEOUT", 0)
    sim_clock.sleep(3600)
    assert not Status(read(fw, "DEVICE_STATUS")) & Status.COMM_LOST


def test_stow_command_and_maintenance_mode(fw, sim_clock):
    write(fw, "HEARTBEAT", 1)
    write(fw, "MODE", Mode.MAINTENANCE, 1)
    write(fw, "COMMAND", Command.STOW)
    assert read(fw, "MODE", 0) == Mode.STOW
    assert read(fw, "MODE", 1) == Mode.MAINTENANCE
    assert read(fw, "COMMAND") == 0  # executed and cleared


def test_rejects_leave_state_unchanged(fw):
    before = fw.read(0, 64)
    with pytest.raises(FirmwareReject) as e:
        fw.write(addr("ACTUAL_ANGLE", 0), [0, 5])  # read-only
    assert e.value.code == 2
    with pytest.raises(FirmwareReject) as e:
        fw.write(addr("TARGET_ANGLE", 0) + 1, [5])  # half of an int32
    assert e.value.code == 2
    with pytest.raises(FirmwareReject) as e:
        fw.write(addr("MODE", 0), [9])  # not a mode
    assert e.value.code == 3
    # A multi-register write with one bad register applies nothing.
    with pytest.raises(FirmwareReject):
        fw.write(addr("SOFT_LIMIT_MIN", 0), encode("SOFT_LIMIT_MIN", 10.0) + encode("SOFT_LIMIT_MAX", 900.0))
    assert fw.read(0, 64) == before
    with pytest.raises(FirmwareReject):
        fw.read(60, 10)


def test_stall_fault_is_reported_and_cleared(fw, sim_clock):
    fw.axes[0].jammed = True
    write(fw, "HEARTBEAT", 1)
    write(fw, "TARGET_ANGLE", 150.0, 0)
    sim_clock.sleep(5)
    write(fw, "HEARTBEAT", 2)
    assert read(fw, "FAULT_CODE", 0) == Fault.STALL
    assert Status(read(fw, "STATUS", 0)) & (Status.FAULT | Status.STALLED)
    fw.axes[0].jammed = False
    write(fw, "COMMAND", Command.CLEAR_FAULT)
    assert read(fw, "FAULT_CODE", 0) == Fault.NONE


def test_single_axis_drive_reports_one_axis(sim_clock):
    fw = DriveFirmware(two_axes()[:1], sim_clock.now)
    assert fw.read(2, 1) == [1]
    with pytest.raises(FirmwareReject):
        write(fw, "TARGET_ANGLE", 1.0, 1)


def test_an_overheated_motor_latches_overtemperature_until_it_has_cooled(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=0.0)
    fw.axes[1].hot = True
    sim_clock.sleep(1.0)
    code = register("FAULT_CODE")
    assert fw.read(code.address(1), 1)[0] == Fault.OVERTEMPERATURE
    status = register("STATUS")
    assert fw.read(status.address(1), 1)[0] & Status.FAULT
    cmd = register("COMMAND")
    fw.write(cmd.address(), encode(cmd, int(Command.CLEAR_FAULT)))
    assert fw.read(code.address(1), 1)[0] == Fault.OVERTEMPERATURE  # still hot
    fw.axes[1].hot = False
    fw.write(cmd.address(), encode(cmd, int(Command.CLEAR_FAULT)))
    assert fw.read(code.address(1), 1)[0] == Fault.NONE


def test_an_overloaded_motor_trips_overcurrent_each_time_it_drives(sim_clock):
    """The emulated drives had never raised OVERCURRENT (a firmware-side audit)."""
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=0.0)
    fw.axes[0].overloaded = True
    start = read(fw, "ACTUAL_ANGLE", 0)
    sim_clock.sleep(1.0)
    assert read(fw, "FAULT_CODE", 0) == Fault.NONE  # at rest: no current, no trip
    write(fw, "TARGET_ANGLE", start + 10.0, 0)
    sim_clock.sleep(1.0)
    assert read(fw, "FAULT_CODE", 0) == Fault.OVERCURRENT
    assert Status(read(fw, "STATUS", 0)) & Status.FAULT
    assert read(fw, "ACTUAL_ANGLE", 0) == pytest.approx(start, abs=0.01)  # it never turned
    write(fw, "COMMAND", int(Command.CLEAR_FAULT))
    assert read(fw, "FAULT_CODE", 0) == Fault.NONE  # the trip clears...
    sim_clock.sleep(1.0)
    assert read(fw, "FAULT_CODE", 0) == Fault.OVERCURRENT  # ...and the next motion trips again
    fw.axes[0].overloaded = False
    write(fw, "COMMAND", int(Command.CLEAR_FAULT))
    sim_clock.sleep(30.0)
    assert read(fw, "FAULT_CODE", 0) == Fault.NONE
    assert read(fw, "ACTUAL_ANGLE", 0) == pytest.approx(start + 10.0, abs=0.03)


def test_home_drives_to_the_index_then_on_to_the_target(sim_clock):
    """Homing had been instant (a firmware-side audit): HOMED is clear while the axis
    drives to its index, and a target written meanwhile is where it goes afterwards."""
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=0.0)
    write(fw, "TARGET_ANGLE", 30.0, 1)
    sim_clock.sleep(90.0)
    assert read(fw, "ACTUAL_ANGLE", 1) == pytest.approx(30.0, abs=0.03)
    write(fw, "COMMAND", int(Command.HOME))
    sim_clock.sleep(5.0)
    status = Status(read(fw, "STATUS", 1))
    assert not status & Status.HOMED and status & Status.MOVING
    assert read(fw, "ACTUAL_ANGLE", 1) < 30.0  # on its way to the index, 0 deg
    write(fw, "TARGET_ANGLE", 20.0, 1)
    assert read(fw, "TARGET_ANGLE", 1) == pytest.approx(20.0)  # the master's target reads back
    lowest = 30.0
    for _ in range(120):
        sim_clock.sleep(0.5)
        lowest = min(lowest, read(fw, "ACTUAL_ANGLE", 1))
    assert lowest == pytest.approx(0.0, abs=0.03)  # it reached the index
    assert Status(read(fw, "STATUS", 1)) & Status.HOMED
    assert read(fw, "ACTUAL_ANGLE", 1) == pytest.approx(20.0, abs=0.03)


def test_a_stow_ends_a_homing_and_a_home_in_stow_is_ignored(sim_clock):
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=0.0)
    write(fw, "TARGET_ANGLE", 30.0, 1)
    sim_clock.sleep(90.0)
    write(fw, "COMMAND", int(Command.HOME))
    sim_clock.sleep(5.0)
    write(fw, "COMMAND", int(Command.STOW))
    status = Status(read(fw, "STATUS", 1))
    assert status & Status.HOMED  # the old reference stands
    assert read(fw, "TARGET_ANGLE", 1) == pytest.approx(fw.axes[1].p.stow_angle)
    write(fw, "COMMAND", int(Command.HOME))
    assert not fw.axes[1].homing and Status(read(fw, "STATUS", 1)) & Status.HOMED
