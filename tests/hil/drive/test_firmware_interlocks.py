"""Interlocks of the emulated firmware that a hostile master must not get past (issue 13,
item 8): stow angles and soft limits are validated, the watchdog cannot be switched off
from the field, a MODE write cannot bypass RESUME, and the watchdog runs on its own
monotonic time, not on a wall clock that steps."""

import pytest

from firmware_protocol import Mode, Status, decode, encode, register
from hil.drive import AxisParams, DriveFirmware, FirmwareReject
from tests.conftest import two_axes


def write(fw, name, value, axis=None):
    fw.write(register(name).address(axis), encode(name, value))


def read(fw, name, axis=None):
    reg = register(name)
    return decode(reg, fw.read(reg.address(axis), reg.words))


@pytest.fixture
def fw(sim_clock):
    return DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=10.0)


def test_stow_angle_outside_the_soft_limits_is_refused(fw):
    lo, hi = read(fw, "SOFT_LIMIT_MIN", 1), read(fw, "SOFT_LIMIT_MAX", 1)
    with pytest.raises(FirmwareReject) as e:
        write(fw, "STOW_ANGLE", hi + 10, 1)
    assert e.value.code == 3
    write(fw, "STOW_ANGLE", (lo + hi) / 2, 1)  # inside: fine


def test_inverted_soft_limits_are_refused_whatever_the_order_of_writes(fw):
    hi = read(fw, "SOFT_LIMIT_MAX", 0)
    with pytest.raises(FirmwareReject):
        write(fw, "SOFT_LIMIT_MIN", hi + 1, 0)
    # both in one write, inverted
    lo_reg, hi_reg = register("SOFT_LIMIT_MIN"), register("SOFT_LIMIT_MAX")
    with pytest.raises(FirmwareReject):
        fw.write(lo_reg.address(0), encode(lo_reg, 50.0) + encode(hi_reg, 40.0))
    # a limit that would leave the stow angle outside is refused too
    stow = read(fw, "STOW_ANGLE", 0)
    with pytest.raises(FirmwareReject):
        write(fw, "SOFT_LIMIT_MAX", stow - 1.0, 0)


def test_the_watchdog_cannot_be_switched_off_outside_maintenance(fw):
    with pytest.raises(FirmwareReject) as e:
        write(fw, "HEARTBEAT_TIMEOUT", 0.0)
    assert e.value.code == 3
    write(fw, "MODE", int(Mode.MAINTENANCE), 0)
    write(fw, "MODE", int(Mode.MAINTENANCE), 1)
    write(fw, "HEARTBEAT_TIMEOUT", 0.0)  # commissioning: allowed


def test_a_mode_write_cannot_leave_stow_without_resume(fw, sim_clock):
    sim_clock.sleep(11.0)  # watchdog: COMM_LOST, STOW
    assert read(fw, "STATUS", 0) & Status.COMM_LOST
    with pytest.raises(FirmwareReject):
        write(fw, "MODE", int(Mode.AUTO), 0)
    assert read(fw, "MODE", 0) == Mode.STOW


def test_the_watchdog_ignores_wall_clock_steps():
    wall = [1_000_000.0]
    mono = [50.0]
    fw = DriveFirmware(two_axes(), lambda: wall[0], heartbeat_timeout=10.0, monotonic=lambda: mono[0])
    wall[0] += 3600.0  # NTP steps the wall clock forward
    fw.update()
    assert not fw.comm_lost
    wall[0] -= 7200.0  # ... and back
    mono[0] += 5.0
    write(fw, "HEARTBEAT", 1)
    mono[0] += 9.0  # 9 s after the heartbeat: alive
    fw.update()
    assert not fw.comm_lost
    mono[0] += 2.0
    fw.update()
    assert fw.comm_lost


def test_negative_parameters_are_refused_at_construction():
    with pytest.raises(ValueError):
        DriveFirmware([AxisParams(max_speed=-1.0)], lambda: 0.0)
    with pytest.raises(ValueError):
        DriveFirmware([AxisParams()], lambda: 0.0, heartbeat_timeout=-5.0)


def test_new_soft_limits_clamp_the_target_in_force(fw, sim_clock):
    """A firmware-side audit's case: with target 170 deg, SOFT_LIMIT_MIN = 175 was taken and
    the axis drove on to 170, outside its new limits."""
    write(fw, "TARGET_ANGLE", 170.0, 0)
    write(fw, "SOFT_LIMIT_MIN", 175.0, 0)
    assert read(fw, "TARGET_ANGLE", 0) == pytest.approx(175.0)
    assert Status(read(fw, "STATUS", 0)) & Status.TARGET_CLAMPED
    sim_clock.sleep(30.0)
    assert read(fw, "ACTUAL_ANGLE", 0) >= 175.0 - 0.01


def test_leaving_maintenance_holds_where_the_service_left_the_axis(fw, sim_clock):
    """It had driven straight to the target set before the maintenance."""
    write(fw, "TARGET_ANGLE", 170.0, 0)
    write(fw, "MODE", int(Mode.MAINTENANCE), 0)
    sim_clock.sleep(1.0)
    here = read(fw, "ACTUAL_ANGLE", 0)
    write(fw, "MODE", int(Mode.AUTO), 0)
    assert read(fw, "TARGET_ANGLE", 0) == pytest.approx(here, abs=0.001)
    sim_clock.sleep(30.0)
    assert read(fw, "ACTUAL_ANGLE", 0) == pytest.approx(here, abs=0.01)
