"""The controller loop against emulated drives, two trackers on one RTU line."""

import math
from datetime import datetime, timezone

import pytest

from controller.clock import SimClock
from controller.config import load_config
from controller.drives import open_drive
from controller.loop import Controller
from controller.sun.source import EphemerisSource
from hil.drive import AxisParams, DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil import truth
from tests.conftest import DEFAULT_CONFIG


@pytest.fixture
def plant():
    cfg = load_config(DEFAULT_CONFIG)
    noon = datetime(2024, 6, 1, 8, 0, tzinfo=timezone.utc)  # ~11:15 local solar time
    clock = SimClock(noon)
    fws = {}
    for tr in cfg.trackers:
        axes = [AxisParams(soft_min=lo, soft_max=hi, hard_min=lo - 5, hard_max=hi + 5,
                           stow_angle=s, initial_angle=s) for (lo, hi), s in zip(tr.soft_limits, tr.stow)]
        fws[tr.name] = DriveFirmware(axes, clock.now, cfg.control.heartbeat_timeout_s)
    with PtyLink.open() as link, ModbusServerThread(
            {tr.device_id: fws[tr.name] for tr in cfg.trackers}, serial_url=link.url):
        drives = {tr.name: open_drive("modbus-rtu", port=link.path, device_id=tr.device_id,
                                      timeout_s=0.3, retries=0) for tr in cfg.trackers}
        ctl = Controller(cfg, drives, EphemerisSource(cfg.site), clock)
        ctl.start()
        yield ctl, fws, clock, cfg
        ctl.close()


def test_tracks_the_true_sun(plant):
    ctl, fws, clock, cfg = plant
    for _ in range(10):
        recs = ctl.cycle()
        clock.sleep(cfg.control.period_s)
    assert all(r.mode == "TRACK" and r.source == "ephemeris" and not r.error for r in recs)
    t = clock.now() - cfg.control.period_s / 2
    clock.advance_to(clock.now())
    st = truth.sun_truth([t], cfg.site.latitude, cfg.site.longitude, cfg.site.altitude)
    sun = st.vectors[0]
    az, el = fws["dual-1"].true_angles()
    # The dual-axis normal is within the lead/lag bound of the true sun.
    assert truth.angle_deg(truth.dual_axis_normal(az, el), sun) < 0.3
    rot = fws["row-1"].true_angles()[0]
    assert truth.row_pointing_error(rot, sun, 180.0, 0.0) < 0.3


def test_dead_drive_does_not_stop_the_other(plant):
    ctl, fws, clock, cfg = plant
    ctl.trackers[1].drive.device_id = 42        # nobody answers there now
    recs = ctl.cycle()
    assert recs[1].error and "failed" in recs[1].error
    assert not recs[0].error and recs[0].targets_deg


def test_night_stows(plant):
    ctl, fws, clock, cfg = plant
    clock.advance_to(datetime(2024, 6, 1, 20, 0, tzinfo=timezone.utc).timestamp())
    recs = ctl.cycle()
    assert all(r.mode == "STOW" and r.reason == "night" for r in recs)
    assert recs[0].targets_deg == cfg.trackers[0].stow


def test_watchdog_stow_is_recovered(plant):
    ctl, fws, clock, cfg = plant
    clock.sleep(cfg.control.heartbeat_timeout_s + 10)   # controller silent: firmware stows
    fws["dual-1"].update()
    assert fws["dual-1"].comm_lost
    ctl.cycle()
    clock.sleep(cfg.control.period_s)
    ctl.cycle()
    assert not fws["dual-1"].comm_lost
    assert int(fws["dual-1"].modes[0]) == 0     # back in AUTO
