"""SCADA sees the controller's plant and its overrides reach the drives (pysunspec2)."""

import pytest
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

from controller.northbound import Northbound
from controller.sunspec import SunSpecServer


@pytest.fixture
def plant(default_plant):
    run, ctl, fws, clock, cfg = default_plant
    return run, ctl, Northbound(ctl, "test-plant"), fws, clock


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
            assert m.N.value == 2 and m.Typ.value == 5  # mixed plant reports Dual
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
    with SunSpecServer(
        bridge.snapshot,
        bridge.on_override,
        host="127.0.0.1",
        port=0,
        writes_enabled=True,
        allow=("127.0.0.1",),
    ) as srv:
        dev = scan(srv.port)
        try:
            blk = dev.models[601][0].tracker[1]  # the single-axis row
            blk.ElCtl.cvalue = 20.0
            blk.Ctl.value = 1  # Manual
            blk.write()
        finally:
            dev.close()
    assert bridge.apply_pending() >= 1
    recs = run(ctl.cycle())
    assert recs[1].mode == "MANUAL" and recs[1].targets_deg == (20.0,)
    assert fws["row-1"].axes[0].target == pytest.approx(20.0)
    assert recs[0].mode == "TRACK"  # the other tracker is untouched
    ctl.set_override(None, "Automatic", None, None)
    assert run(ctl.cycle())[1].mode == "TRACK"


def test_override_is_clamped_to_the_rows_limits(plant):
    run, ctl, bridge, fws, clock = plant
    ctl.set_override(1, "Manual", 80.0, None)
    assert run(ctl.cycle())[1].targets_deg == (55.0,)
    with pytest.raises(ValueError):
        ctl.set_override(0, "Sideways", None, None)


def test_scada_reads_the_plants_civil_time_when_its_zone_is_given(plant):
    from dataclasses import replace

    run, ctl, bridge, fws, clock = plant
    records = run(ctl.cycle())  # 2024-06-01 08:00 UTC
    bridge.publish(records)
    # without a zone: local mean solar time at 48.3364 E, UTC + 3 h 13 min 21 s
    assert bridge.snapshot().local_time.strftime("%Y%m%d %H%M%S") == "20240601 111320"
    ctl.config = replace(ctl.config, site=replace(ctl.config.site, timezone="Asia/Tehran"))
    bridge.publish(records)
    with SunSpecServer(bridge.snapshot, bridge.on_override, host="127.0.0.1", port=0) as srv:
        dev = scan(srv.port)
        try:
            m = dev.models[601][0]
            assert (m.DtLoc.value, m.TmLoc.value, m.Day.value) == ("20240601", "113000", 153)  # UTC+3:30
        finally:
            dev.close()
    ctl.config = replace(ctl.config, site=replace(ctl.config.site, timezone="Europe/Oslo"))
    bridge.publish(records)
    assert bridge.snapshot().local_time.strftime("%H%M%S") == "100000"  # summer time, UTC+2


def test_an_override_kept_over_a_restart_reads_manual_before_the_first_cycle(default_plant):
    _run, ctl, _fws, _clock, _cfg = default_plant
    ctl.set_override(1, "Manual", 20.0, None)  # put back from the state folder at start-up
    snap = Northbound(ctl, "test-plant").snapshot()  # served at once; no cycle published yet
    row, dual = snap.trackers[1], snap.trackers[0]
    assert (row.mode, row.manual_el_deg) == ("MANUAL", 20.0)
    assert dual.mode == "STOW" and dual.manual_el_deg is None
