"""What faults revealed in the control loop (controller/loop.py, controller/health.py), on the
default plant over a real pty: a drive that rebooted between two cycles was left in the
STOW its factory watchdog chose; a link waiting for its reconnection counted every cycle
of the wait as a new failure, so the wait doubled each cycle and the drive never came
back.  Both tests failed before."""

import time

import pytest

from hil.drive import AxisParams


def test_a_drive_that_rebooted_between_cycles_is_configured_and_resumed(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    run(ctl.cycle())
    clock.sleep(20.0)
    fw = fws["row-1"]
    angle = fw.true_angles()[0]
    # power cycle in place: fresh firmware where the panel is, factory 10-s watchdog
    fw.__init__([AxisParams(initial_angle=angle)], clock.now, heartbeat_timeout=10.0)
    recs = []
    for _ in range(3):
        clock.sleep(cfg.control.period_s)  # its watchdog fires long before the next cycle
        recs.append(run(ctl.cycle())[1])
    assert any(e["kind"] == "drive_reboot" and e["tracker"] == "row-1" for e in ctl.events)
    assert fw.heartbeat_timeout == cfg.control.heartbeat_timeout_s  # configured again
    assert recs[-1].health == "ok" and recs[-1].axis_modes == ("AUTO",)
    assert recs[1].health == "ok"  # back within two cycles


def silence_row(plant, cycles: int):
    """row-1 answers after the link's 0.3-s timeout (none) for ``cycles`` periods: its runtime."""
    run, ctl, fws, clock, cfg = plant
    run(ctl.cycle())
    fws["row-1"].response_delay_s = 1.0
    for _ in range(cycles):
        clock.sleep(cfg.control.period_s)
        run(ctl.cycle())
    return ctl.trackers[1]


def test_a_link_waiting_to_reconnect_does_not_push_its_reconnection_back(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    tr = silence_row(default_plant, 3)
    assert tr.health.state.value == "lost" and not tr.configured
    due = tr.health.reconnect_at
    clock.sleep(cfg.control.period_s / 2)
    rec = run(ctl.cycle())[1]  # waiting: nothing tried
    assert "link down" in rec.error
    assert tr.health.reconnect_at == due and rec.health_reason.count("link down") == 0
    fws["row-1"].response_delay_s = 0.0  # the drive answers again
    for _ in range(2):
        clock.sleep(cfg.control.period_s / 2)
        rec = run(ctl.cycle())[1]
    assert not rec.error and tr.configured


def test_a_drive_back_after_a_long_outage_is_reconnected_the_next_cycle(default_plant):
    """The reconnection backoff grows through a long outage (one period, doubling); once the
    drive answers again, the cycle's probe reconnects it at once instead of waiting out the
    backoff (the soak: a CANopen row back 225 s after its bus fault cleared)."""
    run, ctl, fws, clock, cfg = default_plant
    tr = silence_row(default_plant, 12)
    assert tr.health.state.value == "lost" and tr.health.backoff_s >= 4 * cfg.control.period_s
    assert tr.health.reconnect_at - clock.monotonic() > 2 * cfg.control.period_s
    fws["row-1"].response_delay_s = 0.0  # the drive answers again
    time.sleep(1.5)  # (wall clock) its late answers to the last probe have gone by
    clock.sleep(cfg.control.period_s)
    rec = run(ctl.cycle())[1]
    assert not rec.error and tr.configured and rec.health == "ok"
    clock.sleep(cfg.control.period_s)  # its watchdog's stow was resumed: tracking again
    rec = run(ctl.cycle())[1]
    assert not rec.error and rec.axis_modes == ("AUTO",)
    assert fws["row-1"].axes[0].target == pytest.approx(rec.targets_deg[0], abs=0.01)
