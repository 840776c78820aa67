"""A drive's health from what it says: readings that cannot be, and stows that do not lift.

Each case is one an audit of bad wire data found (2026-12-01); each failed on the code before."""

import math

import pytest

from controller.drives.base import AxisState, DriveState
from controller.health import DriveHealth, Health, implausible_axes
from firmware_protocol import Command, Fault, Mode, Status

LIMITS = ((0.0, 360.0), (0.0, 90.0))


NO_STATUS = Status(0)


def state(*angles, mode=Mode.AUTO, status=NO_STATUS, fault=Fault.NONE):
    axes = tuple(AxisState(a, a, 0.0, status, fault, mode) for a in angles)
    return DriveState(len(axes), axes, status)


@pytest.mark.parametrize(
    ("angles", "bad"),
    [
        ((224.0, 21.0), ""),
        ((365.0, -5.0), ""),  # an overshoot past the travel is not a fault
        ((1e6, -1e6), "axis 0 reads 1000000.00 deg, outside its travel [0, 360]"),
        ((-2147483.648, 21.0), "axis 0 reads -2147483.65 deg"),  # an int32 sentinel in mdeg
        ((224.0, math.nan), "axis 1 reads nan deg"),
    ],
)
def test_readings_outside_the_travel_are_named(angles, bad):
    got = implausible_axes(state(*angles), LIMITS)
    assert (got == "") if not bad else (bad in got and got.endswith("(encoder or firmware fault)"))


def test_a_drive_that_reads_an_impossible_angle_is_degraded():
    """It had been ok, 0 errors, with 1e6 deg read every cycle."""
    h = DriveHealth()
    h.assess(state(1e6, 21.0), 0.0, weather_stow=False, limits=LIMITS)
    assert h.state == Health.DEGRADED and "axis 0 reads 1000000.00 deg" in h.reason


def test_a_reading_that_moves_faster_than_the_drive_can_is_named():
    """An audit's case: a drive reporting a 120-deg slew between two one-second cycles,
    where its speed limit is 1 deg/s, had been ok."""
    h = DriveHealth()
    speeds = (1.0, 0.5)

    def see(t, *angles, status=Status.HOMED):
        h.assess(state(*angles, status=status), t, weather_stow=False, limits=LIMITS, max_speeds=speeds)

    see(0.0, 100.0, 20.0)
    see(1.0, 101.0, 20.5)
    assert h.state == Health.OK, h.reason  # at its speed limit: a slew
    see(2.0, 221.0, 20.5)
    assert h.state == Health.DEGRADED
    assert (
        h.reason
        == "axis 0 reading jumped 120.00 deg in 1.0 s, faster than its 1 deg/s (encoder or firmware fault)"
    )
    see(3.0, 221.0, 20.5)
    assert h.state == Health.OK  # it stays there: the new reading is the reference
    see(123.0, 160.0, 50.0)  # a long gap (a link lost for minutes) allows a long slew
    assert h.state == Health.OK, h.reason
    # homing re-references the encoder: a jump while HOMED is clear, or as it comes back, is no fault
    see(124.0, 165.0, 50.0, status=Status(0))
    see(125.0, 172.0, 50.0, status=Status(0))
    assert h.state == Health.OK, h.reason
    see(126.0, 178.0, 50.0)
    assert h.state == Health.OK, h.reason
    see(127.0, 190.0, 50.0)  # referenced on both readings: judged again
    assert h.state == Health.DEGRADED
    # without the drive's speed limit (a backend that cannot read it) nothing is judged
    h2 = DriveHealth()
    h2.assess(state(100.0, 20.0, status=Status.HOMED), 0.0, weather_stow=False, limits=LIMITS)
    h2.assess(state(221.0, 20.0, status=Status.HOMED), 1.0, weather_stow=False, limits=LIMITS)
    assert h2.state == Health.OK


def test_a_watchdog_stow_that_does_not_lift_is_said():
    """It had been ok, with a RESUME every cycle, the drive stowed the whole run."""
    h = DriveHealth()
    stuck = state(180.0, 90.0, mode=Mode.STOW, status=Status.COMM_LOST)
    sent = [h.assess(stuck, float(t), weather_stow=False, limits=LIMITS) for t in range(4)]
    assert all(cmds == [Command.RESUME] for cmds in sent)
    assert h.state == Health.DEGRADED and "does not lift after 3 RESUMEs (COMM_LOST still set" in h.reason
    h.assess(state(180.0, 90.0), 5.0, weather_stow=False, limits=LIMITS)
    assert h.state == Health.OK and h.resumes_unanswered == 0


def test_a_stow_with_a_fault_latched_is_not_resumed_until_it_clears():
    h = DriveHealth(watchdog_stow=True)
    faulted = state(180.0, 90.0, mode=Mode.STOW, status=Status.FAULT, fault=Fault.HARD_LIMIT)
    cmds = h.assess(faulted, 0.0, weather_stow=False, limits=LIMITS)
    assert Command.RESUME not in cmds and Command.CLEAR_FAULT in cmds
    assert "resumed once the fault clears" in h.reason
    cmds = h.assess(state(180.0, 90.0, mode=Mode.STOW), 1.0, weather_stow=False, limits=LIMITS)
    assert cmds == [Command.RESUME]


def test_an_axis_that_does_not_follow_its_target_is_named():
    """An audit's case: a drive that took targets and stayed at 100/30 was ok all run."""
    h = DriveHealth()

    def reading(az, target_az):
        axes = (
            AxisState(az, target_az, 0.0, NO_STATUS, Fault.NONE, Mode.AUTO),
            AxisState(30.0, 30.0, 0.0, NO_STATUS, Fault.NONE, Mode.AUTO),
        )
        return DriveState(2, axes)

    for t in range(0, 31, 10):
        h.assess(reading(100.0, 224.0), float(t), weather_stow=False, limits=LIMITS)
    assert h.state == Health.DEGRADED
    assert "axis 0 does not follow its target (at 100.00 deg, target 224.00, for 30 s)" in h.reason
    h.assess(reading(101.0, 224.0), 40.0, weather_stow=False, limits=LIMITS)  # moving again
    assert h.state == Health.OK
    for t in range(40, 200, 10):  # a long slew that moves is never flagged
        h.assess(reading(101.0 + (t - 40) * 0.5, 224.0), float(t), weather_stow=False, limits=LIMITS)
    assert h.state == Health.OK


def test_a_drive_that_starts_a_slew_after_a_stow_is_not_flagged():
    """The clock starts at the first reading away from the target, not at the stow before."""
    h = DriveHealth()
    h.assess(state(0.0, 90.0, mode=Mode.STOW), 0.0, weather_stow=False, limits=LIMITS)
    axes = (AxisState(0.0, -9.87, 0.0, NO_STATUS, Fault.NONE, Mode.AUTO),) * 2
    h.assess(DriveState(2, axes), 60.0, weather_stow=False, limits=((-55.0, 55.0),) * 2)
    assert "does not follow" not in h.reason


def test_another_target_latched_is_named_unless_the_drive_homes():
    h = DriveHealth()
    axes = (AxisState(100.0, 130.0, 0.0, Status.HOMED, Fault.NONE, Mode.AUTO),)
    h.assess(DriveState(1, axes), 0.0, weather_stow=False, limits=LIMITS[:1], targets=(100.0,))
    assert h.state == Health.DEGRADED and "axis 0 works to 130.000 deg, 100.000 commanded" in h.reason
    homing = (AxisState(100.0, 130.0, 0.0, Status(0), Fault.NONE, Mode.AUTO),)  # to its index
    h.assess(DriveState(1, homing), 1.0, weather_stow=False, limits=LIMITS[:1], targets=(100.0,))
    assert h.state == Health.OK, h.reason


def test_a_fault_that_comes_back_after_each_clear_needs_service():
    """An over-current under a load that lasts: each clear works, and the next motion
    trips it again, so every other reading is clean.  The clear count had restarted at
    each clean reading, and the drive was cleared (and tripped) forever."""
    h = DriveHealth()
    tripped = state(180.0, 30.0, status=Status.FAULT, fault=Fault.OVERCURRENT)
    clean = state(180.0, 30.0)
    now = 0.0
    for _ in range(4):
        h.assess(tripped, now, weather_stow=False, limits=LIMITS)
        h.assess(clean, now + 60.0, weather_stow=False, limits=LIMITS)
        now += 120.0
    cmds = h.assess(tripped, now, weather_stow=False, limits=LIMITS)
    assert h.state == Health.LOST and "needs service" in h.reason, h.reason
    assert "OVERCURRENT" in h.reason
    assert cmds == [Command.CLEAR_FAULT]  # the slow retry goes on: the load may be gone
    # a drive that then runs clean for a while starts a fresh count
    for t in (60.0, 120.0, 180.0, 240.0):
        h.assess(clean, now + t, weather_stow=False, limits=LIMITS)
    h.assess(tripped, now + 300.0, weather_stow=False, limits=LIMITS)
    assert h.state == Health.DEGRADED and "clear 1/3" in h.reason, h.reason
