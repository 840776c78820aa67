"""The loop under faults and weather (issue 13): what a hostile probe found, and wind stow.

Each defect test here failed on the code before the fix (see the commit that adds it)."""

from dataclasses import replace

import pytest

from controller.northbound import Northbound
from controller.weather import WindConfig, WindSample
from firmware_protocol import Command, Mode, encode, register


def command(fw, cmd):
    reg = register("COMMAND")
    fw.write(reg.address(), encode(reg, int(cmd)))


def test_a_stow_by_someone_else_is_not_undone(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)  # a local wind switch / maintenance panel
    for _ in range(3):
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
    assert fws["row-1"].modes[0] == Mode.STOW
    assert recs[1].health == "degraded" and "left stowed" in recs[1].health_reason
    assert recs[0].health == "ok" and fws["dual-1"].modes[0] == Mode.AUTO


def test_a_watchdog_stow_is_resumed_after_a_heartbeat_cleared_comm_lost(default_plant):
    """On a CAN bus the master's heartbeat is a frame of its own: frames lost to a bus fault
    fire a drive's watchdog while the master's SDOs get through, and the next heartbeat
    clears COMM_LOST before the master looks. The 30-day soak found both CANopen rows left
    in that STOW for 28 min ("stowed by a local switch or another master"); the drive now
    latches WATCHDOG_STOW until it leaves STOW."""
    from firmware_protocol import Status

    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    fw = fws["row-1"]
    fw._enter_comm_lost()  # the drive's watchdog fired (heartbeats lost, the rest heard)
    hb = register("HEARTBEAT")
    fw.write(hb.address(), encode(hb, (fw.heartbeat + 1) & 0xFFFF))  # the next heartbeat
    assert fw.modes[0] == Mode.STOW and not fw.comm_lost
    assert fw.status(0) & Status.WATCHDOG_STOW
    clock.sleep(cfg.control.period_s)
    recs = run(ctl.cycle())
    assert fw.modes[0] == Mode.AUTO, recs[1].health_reason
    assert not fw.status(0) & Status.WATCHDOG_STOW
    clock.sleep(cfg.control.period_s)
    recs = run(ctl.cycle())
    assert recs[1].health == "ok" and recs[1].mode == "TRACK"


def test_a_master_stow_during_a_watchdog_stow_is_the_masters(default_plant):
    from firmware_protocol import Status

    run, ctl, fws, clock, cfg = default_plant
    fw = fws["row-1"]
    fw._enter_comm_lost()
    command(fw, Command.STOW)  # a local switch stows it again: that stow is not ours
    assert not fw.status(0) & Status.WATCHDOG_STOW


def test_a_drive_fault_is_named_cleared_and_alarmed(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    bridge = Northbound(ctl, "p")
    run(ctl.cycle())
    ax = fws["dual-1"].axes[1]
    ax.hard_limit = True  # the elevation axis hit its limit switch
    ax.target = ax.output = 45.0
    clock.sleep(cfg.control.period_s)
    recs = run(ctl.cycle())
    assert recs[0].health == "degraded"
    assert "axis 1 fault HARD_LIMIT" in recs[0].health_reason and "clear 1/3" in recs[0].health_reason
    bridge.publish(recs)
    assert bridge.snapshot().trackers[0].alarm_bits & 1  # SunSpec Alm SetPoint
    assert not ax.hard_limit  # CLEAR_FAULT went out and the cause is gone
    clock.sleep(cfg.control.period_s)
    recs = run(ctl.cycle())
    assert recs[0].health == "ok"


def cycles_until_row_ok(plant, limit: int):
    """Run cycles a period apart until row-1 is healthy (at most ``limit``): (cycles, records)."""
    run, ctl, _fws, clock, cfg = plant
    periods = 0
    while periods < limit:
        clock.sleep(cfg.control.period_s)
        periods += 1
        recs = run(ctl.cycle())
        if recs[1].health == "ok":
            break
    return periods, recs


def test_a_fault_that_survives_the_clears_leaves_the_drive_lost(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    ax = fws["row-1"].axes[0]
    for _ in range(8):
        ax.hard_limit = True  # keeps tripping (a broken switch)
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
    assert recs[1].health == "lost" and "needs service" in recs[1].health_reason
    health = ctl.trackers[1].health
    # three clears, then one every service_retry_s (not every cycle when the period is short)
    expected = (
        3 + (8 * cfg.control.period_s - 3 * health.policy.clear_interval_s) // health.policy.service_retry_s
    )
    assert 3 < health.fault_clears <= expected + 1
    # the switch stops tripping (repaired): the next clear brings the drive back by itself,
    # within two control periods of the repair however long the fault lasted
    ax.hard_limit = False
    ax.limit_stuck = False
    periods, recs = cycles_until_row_ok(default_plant, 16)
    assert recs[1].health == "ok" and not ax.hard_limit
    assert periods * cfg.control.period_s <= max(
        2 * cfg.control.period_s, health.policy.service_retry_s + cfg.control.period_s
    )


def test_a_long_stall_is_back_within_two_periods_once_its_jam_frees(default_plant):
    """A jam that outlasts the quick clears (ice, 20 minutes): the drive is back within two
    control periods of the jam freeing (the soak: 2.83 periods with the doubling retry)."""
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    ax = fws["row-1"].axes[0]
    ax.jammed = True
    ax.stalled = True
    for _ in range(int(1200 // cfg.control.period_s)):
        clock.sleep(cfg.control.period_s)
        recs = run(ctl.cycle())
    assert recs[1].health == "lost" and "needs service" in recs[1].health_reason
    ax.jammed = False  # the ice melts
    periods, recs = cycles_until_row_ok(default_plant, 4)
    assert recs[1].health == "ok", recs[1].health_reason
    assert periods * cfg.control.period_s <= 2 * max(cfg.control.period_s, 60.0)


class FakeAnemometer:
    """Stands in for the Modbus anemometer: a gust value set by the test."""

    def __init__(self):
        self.gust = 3.0
        self.fail = False

    async def read(self, t):
        if self.fail:
            from controller.drives.base import DriveCommError

            raise DriveCommError("anemometer: no answer")
        return WindSample(t, self.gust * 0.7, self.gust, self.gust * 0.6)

    async def close(self):
        pass


@pytest.fixture
def windy(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    wind = WindConfig(
        link="rs485-1",
        device_id=11,
        resume_dwell_s=600,
        poll_s=5,
        silent_timeout_s=60,
        single_axis_deg=0.0,
        dual_axis_elevation_deg=90.0,
    )
    ctl.config = replace(cfg, wind=wind)
    from controller.safety import SafetyState

    ctl.safety = SafetyState(wind, cfg.stow, clock.now())
    ctl.anemometer = FakeAnemometer()
    return run, ctl, fws, clock, ctl.config


def test_a_gust_stows_every_drive_at_once_and_the_plant_resumes_after_the_dwell(windy):
    run, ctl, fws, clock, cfg = windy
    run(ctl.cycle())
    ctl.set_override(0, "Manual", 45.0, 100.0)  # an operator's setpoint...
    ctl.anemometer.gust = 24.0
    clock.sleep(10)
    state = run(ctl.poll_weather())  # between two cycles
    assert state.stow and "gust 24.0" in state.reason
    assert all(fw.modes[k] == Mode.STOW for fw in fws.values() for k in range(len(fw.axes)))
    kinds = [e["kind"] for e in ctl.events]
    assert kinds.count("stow_confirmed") == 2
    clock.sleep(50)
    recs = run(ctl.cycle())
    assert all(r.mode == "STOW" and r.reason.startswith("wind") for r in recs)  # ...is outranked
    ctl.anemometer.gust = 5.0
    for _ in range(11):  # calm for 10 min: still stowed
        clock.sleep(55)
        run(ctl.poll_weather())
        recs = run(ctl.cycle())
    assert recs[1].mode == "STOW"
    clock.sleep(60)
    run(ctl.poll_weather())
    ctl.set_override(None, "Automatic", None, None)
    recs = run(ctl.cycle())
    assert all(r.mode == "TRACK" for r in recs)
    assert all(fw.modes[0] == Mode.AUTO for fw in fws.values())


def test_a_silent_anemometer_stows_the_plant(windy):
    run, ctl, fws, clock, cfg = windy
    ctl.anemometer.fail = True
    for _ in range(13):
        clock.sleep(5)
        state = run(ctl.poll_weather())
    assert state.stow and "anemometer silent" in state.reason
    assert all(fw.modes[0] == Mode.STOW for fw in fws.values())


def test_realtime_run_serves_the_whole_duration_whatever_the_period(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    ctl.realtime = True
    ctl.config = replace(cfg, control=replace(cfg.control, period_s=60.0, heartbeat_timeout_s=180.0))
    import time

    t0 = time.monotonic()
    res = run(ctl.run(1.5))
    assert time.monotonic() - t0 >= 1.5 and res["cycles"] == 1


def test_the_schedule_ignores_wall_clock_steps(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    ctl.realtime = True
    ctl.config = replace(cfg, control=replace(cfg.control, period_s=0.5, heartbeat_timeout_s=5.0))
    clock.step_wall(3600.0)  # NTP jumps an hour forward ...
    import time

    t0 = time.monotonic()
    res = run(ctl.run(1.2))
    assert 1.2 <= time.monotonic() - t0 < 3.0 and res["cycles"] in (2, 3)
    clock.step_wall(-7200.0)  # ... and back
    res = run(ctl.run(1.2))
    assert res["cycles"] >= 4


def test_a_drive_that_reboots_is_configured_again(default_plant):
    from hil.drive import DriveFirmware

    run, ctl, fws, clock, cfg = default_plant
    fw = fws["row-1"]
    run(ctl.cycle())
    clock.sleep(cfg.control.heartbeat_timeout_s / 3)
    run(ctl.cycle())
    # power cycle: the same firmware object comes back with its power-up state
    fresh = DriveFirmware([ax.p for ax in fw.axes], clock.now, heartbeat_timeout=10.0)
    fw.__dict__.update(fresh.__dict__)
    fw.axes[0].p.soft_max = 90.0  # power-up default, not the configured 55
    for _ in range(2):
        clock.sleep(cfg.control.heartbeat_timeout_s / 3)
        recs = run(ctl.cycle())
    assert any(e["kind"] == "drive_reboot" and e["tracker"] == "row-1" for e in ctl.events)
    assert fw.heartbeat_timeout == cfg.control.heartbeat_timeout_s
    assert fw.axes[0].p.soft_max == 55.0 and not recs[1].error


def test_a_calibrate_waits_for_a_stow_to_end(default_plant):
    """An audit's case: SCADA's hail stow request and a Calibrate in the same second; the
    next cycle homed both drives during the hail stow (homing moves the axis to its index)."""
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    for fw in fws.values():
        fw.homed = [False] * len(fw.homed)  # to see a HOME arrive
    ctl.safety.request("sunspec", "hail")
    ctl.set_override(None, "Calibrate", None, None)
    for _ in range(3):
        clock.sleep(cfg.control.period_s)
        run(ctl.cycle())
    assert not any(any(fw.homed) for fw in fws.values())
    ctl.safety.request("sunspec", None)  # the stow ends: the drives home
    clock.sleep(cfg.control.period_s)
    run(ctl.cycle())
    assert all(ax.homing for fw in fws.values() for ax in fw.axes)  # under way: to the index
    cycles_to_home(run, ctl, fws, clock, cfg)


def cycles_to_home(run, ctl, fws, clock, cfg, names=None, most=12) -> int:
    """Cycles until the drives (``names``, else all) have homed and are back on the
    controller's targets (within a cycle's step of the sun); fails after ``most`` cycles."""
    names = list(fws) if names is None else names
    for n in range(1, most + 1):
        clock.sleep(cfg.control.period_s)
        recs = {r.tracker: r for r in run(ctl.cycle())}
        done = [all(fws[t].homed) and not any(ax.homing for ax in fws[t].axes) for t in names]
        on_target = [
            all(abs(a - t) < 1.5 for a, t in zip(fws[name].true_angles(), recs[name].targets_deg))
            for name in names
        ]
        if all(done) and all(on_target):
            return n
    raise AssertionError(
        f"not homed and back on target after {most} cycles: {[fw.homed for fw in fws.values()]}"
    )


def test_a_calibrate_leaves_a_drive_in_someone_elses_stow_unhomed(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    command(fws["row-1"], Command.STOW)  # a local switch
    clock.sleep(cfg.control.period_s)
    run(ctl.cycle())
    for fw in fws.values():
        fw.homed = [False] * len(fw.homed)
    ctl.set_override(None, "Calibrate", None, None)
    cycles_to_home(run, ctl, fws, clock, cfg, names=["dual-1"])
    assert fws["row-1"].homed == [False] and not fws["row-1"].axes[0].homing


def test_a_reboot_whose_configuration_fails_is_configured_again(default_plant):
    """An audit's case: the configuration after a reboot failed once, the drive stayed
    'configured' and ran on its factory watchdog and limits, reported ok."""
    from controller.drives.base import DriveCommError
    from hil.drive import DriveFirmware

    run, ctl, fws, clock, cfg = default_plant
    fw, tr = fws["row-1"], next(t for t in ctl.trackers if t.cfg.name == "row-1")
    run(ctl.cycle())
    clock.sleep(cfg.control.heartbeat_timeout_s / 3)
    run(ctl.cycle())
    fresh = DriveFirmware([ax.p for ax in fw.axes], clock.now, heartbeat_timeout=10.0)
    fw.__dict__.update(fresh.__dict__)
    fw.axes[0].p.soft_max = 90.0
    real, calls = tr.drive.configure, []

    async def flaky(**kw):
        calls.append(kw)
        if len(calls) == 1:
            raise DriveCommError("row-1: soft limit write refused")
        await real(**kw)

    tr.drive.configure = flaky
    for _ in range(4):
        clock.sleep(cfg.control.heartbeat_timeout_s / 3)
        recs = run(ctl.cycle())
    assert len(calls) >= 2 and tr.configured
    assert fw.heartbeat_timeout == cfg.control.heartbeat_timeout_s and fw.axes[0].p.soft_max == 55.0
    assert not recs[1].error
