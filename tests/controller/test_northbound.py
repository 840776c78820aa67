"""SCADA sees the controller's plant and its overrides reach the drives (pysunspec2)."""

import asyncio
from datetime import datetime, timezone

import pytest
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

from controller.clock import SimClock
from controller.config import load_config
from controller.drives import open_drive
from controller.loop import Controller
from controller.northbound import Northbound
from controller.sun.source import EphemerisSource
from controller.sunspec import SunSpecServer
from hil.drive import AxisParams, DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from tests.conftest import DEFAULT_CONFIG


@pytest.fixture
def plant():
    cfg = load_config(DEFAULT_CONFIG)
    clock = SimClock(datetime(2024, 6, 1, 8, 0, tzinfo=timezone.utc))
    fws = {tr.name: DriveFirmware(
        [AxisParams(soft_min=lo, soft_max=hi, hard_min=lo - 5, hard_max=hi + 5, stow_angle=s,
                    initial_angle=s) for (lo, hi), s in zip(tr.soft_limits, tr.stow)],
        clock.now, cfg.control.heartbeat_timeout_s) for tr in cfg.trackers}
    loop = asyncio.new_event_loop()
    with PtyLink.open() as link, ModbusServerThread(
            {tr.device_id: fws[tr.name] for tr in cfg.trackers}, serial_url=link.url):
        async def make():
            drives = {tr.name: open_drive("modbus-rtu", port=link.path, device_id=tr.device_id,
                                          timeout_s=0.3, retries=0) for tr in cfg.trackers}
            ctl = Controller(cfg, drives, EphemerisSource(cfg.site), clock)
            await ctl.start()
            return ctl

        ctl = loop.run_until_complete(make())
        bridge = Northbound(ctl, "test-plant")
        yield loop.run_until_complete, ctl, bridge, fws, clock
        loop.run_until_complete(ctl.close())
    loop.close()


def scan(port):
    dev = SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr="127.0.0.1", ipport=port, timeout=2)
    dev.scan()
    return dev


def test_scada_reads_the_live_plant(plant):
    run, ctl, bridge, fws, clock = plant
    bridge.publish(run(ctl.cycle()))
    with SunSpecServer(bridge.snapshot, bridge.on_override, host="127.0.0.1", port=0) as srv:
        dev = scan(srv.port)
        try:
            m = dev.models[601][0]
            assert m.N.value == 2 and m.Typ.value == 5     # mixed plant reports Dual
            dual, row = m.tracker[0], m.tracker[1]
            assert dual.Id.value == "dual-1" and row.Id.value == "row-1"
            assert dual.AzTrgt.cvalue == pytest.approx(ctl.trackers[0].last_targets[0], abs=1e-3)
            assert dual.ElTrgt.cvalue == pytest.approx(ctl.trackers[0].last_targets[1], abs=1e-3)
            assert row.ElTrgt.cvalue == pytest.approx(ctl.trackers[1].last_targets[0], abs=1e-3)
            assert row.AzTrgt.value is None
        finally:
            dev.close()


def test_operator_override_reaches_the_drive_and_automatic_releases_it(plant):
    run, ctl, bridge, fws, clock = plant
    bridge.publish(run(ctl.cycle()))
    with SunSpecServer(bridge.snapshot, bridge.on_override, host="127.0.0.1", port=0,
                       writes_enabled=True, allow=("127.0.0.1",)) as srv:
        dev = scan(srv.port)
        try:
            blk = dev.models[601][0].tracker[1]            # the single-axis row
            blk.ElCtl.cvalue = 20.0
            blk.Ctl.value = 1                              # Manual
            blk.write()
        finally:
            dev.close()
    assert bridge.apply_pending() >= 1
    recs = run(ctl.cycle())
    assert recs[1].mode == "MANUAL" and recs[1].targets_deg == (20.0,)
    assert fws["row-1"].axes[0].target == pytest.approx(20.0)
    assert recs[0].mode == "TRACK"                         # the other tracker is untouched
    ctl.set_override(None, "Automatic", None, None)
    assert run(ctl.cycle())[1].mode == "TRACK"


def test_override_is_clamped_to_the_rows_limits(plant):
    run, ctl, bridge, fws, clock = plant
    ctl.set_override(1, "Manual", 80.0, None)
    assert run(ctl.cycle())[1].targets_deg == (55.0,)
    with pytest.raises(ValueError):
        ctl.set_override(0, "Sideways", None, None)
