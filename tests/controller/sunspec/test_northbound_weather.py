"""The controller's weather reaches SCADA and SCADA's snow/hail request reaches the
controller (issue 13): the Northbound bridge on a Controller driving emulated drives, a
pysunspec2 client with heliotrack's model 64601 on 127.0.0.1."""

from __future__ import annotations

import pytest
import sunspec2.device as sunspec_device
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP
from sunspec2.modbus.modbus import ModbusClientError

from controller.northbound import Northbound
from controller.safety import SafetyState
from controller.sunspec import SunSpecServer, write_model_json
from controller.sunspec.vendor import WEATHER_MODEL_ID
from controller.weather import WindConfig, WindSample, WindState

HOST = "127.0.0.1"


@pytest.fixture
def scada(default_plant, tmp_path):
    """(run, controller, bridge, firmwares, clock, pysunspec2 device) with writes allowed."""
    run, ctl, fws, clock, _cfg = default_plant
    bridge = Northbound(ctl, "wx-plant")
    before = list(sunspec_device.get_model_defs_path())
    write_model_json(tmp_path)
    sunspec_device.set_model_defs_path([str(tmp_path), *before])
    srv = SunSpecServer(
        bridge.snapshot, bridge.on_override, host=HOST, port=0, writes_enabled=True, allow=(HOST,)
    ).start()
    dev = SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr=HOST, ipport=srv.port, timeout=2)
    try:
        bridge.publish(run(ctl.cycle()))
        dev.scan()
        yield run, ctl, bridge, fws, clock, dev
    finally:
        dev.close()
        srv.stop()
        sunspec_device.set_model_defs_path(before)


def _override(dev, el: float) -> None:
    blk = dev.models[601][0].tracker[1]
    blk.ElCtl.cvalue = el
    blk.Ctl.value = 1
    blk.write()


def test_a_scada_hail_request_stows_the_plant_and_can_be_withdrawn(scada):
    run, ctl, bridge, fws, clock, dev = scada
    wx = dev.models[WEATHER_MODEL_ID][0]
    assert (wx.Stow.value, wx.Alm.value, wx.StowReq.value) == (0, 0, 0)
    wx.StowReq.value = 2  # HAIL
    wx.write()
    assert bridge.apply_pending() == 1
    assert ctl.safety.requests == {"sunspec": "hail"}
    recs = run(ctl.cycle())
    bridge.publish(recs)
    assert all(r.mode == "STOW" and r.reason == "hail stow (sunspec)" for r in recs)
    assert recs[0].targets_deg == (180.0, 10.0) and recs[1].targets_deg == (55.0,)  # hail angles
    assert fws["row-1"].axes[0].target == pytest.approx(55.0)
    wx.read()
    assert wx.Stow.value == 2 and wx.Rsn.value == "hail stow (sunspec)"
    assert wx.Alm.value == 0b10100  # HailStow, StowRequested
    # an override during the hail stow: refused with "device busy", nothing queued
    with pytest.raises(ModbusClientError, match="exception:? 6"):
        _override(dev, 20.0)
    assert bridge.apply_pending() == 0
    wx.StowReq.value = 0  # withdrawn
    wx.write()
    assert bridge.apply_pending() == 1 and ctl.safety.requests == {}
    clock.sleep(60.0)
    recs = run(ctl.cycle())
    bridge.publish(recs)
    assert recs[1].mode == "TRACK"
    wx.read()
    assert (wx.Stow.value, wx.Alm.value, wx.StowReq.value) == (0, 0, 0)
    _override(dev, 20.0)  # and overrides are taken again
    assert bridge.apply_pending() == 2 and ctl.overrides[1] == (20.0,)  # ElCtl, Ctl: two writes


def test_an_operator_snow_stow_is_seen_by_scada(scada):
    run, ctl, bridge, fws, clock, dev = scada
    ctl.safety.request("operator", "snow")
    bridge.publish(run(ctl.cycle()))
    wx = dev.models[WEATHER_MODEL_ID][0]
    wx.read()
    assert wx.Stow.value == 3 and wx.Alm.value == 0b01000 and wx.StowReq.value == 0
    assert wx.Rsn.value == "snow stow (operator)"


def test_a_wind_stow_between_cycles_refuses_overrides_at_once(scada):
    """The loop stows on a gust between cycles (poll_weather); the bridge does not wait for
    the next publication to refuse overrides and to show the wind stow."""
    run, ctl, bridge, fws, clock, dev = scada
    first = bridge.snapshot()
    assert bridge.snapshot() is first  # the same object while nothing changes
    ctl.safety.wind = WindState(True, True, "wind: gust 27.0 m/s, 10-min mean 16.0 m/s")
    live = bridge.snapshot()
    assert live.weather.stow == "wind" and "gust 27.0" in live.weather.reason
    assert bridge.snapshot() is live
    with pytest.raises(ModbusClientError, match="exception:? 6"):
        _override(dev, 20.0)
    wx = dev.models[WEATHER_MODEL_ID][0]
    wx.read()
    assert wx.Stow.value == 1 and wx.Alm.value & 1


def test_a_lost_anemometer_alarms_on_scada(scada):
    run, ctl, bridge, fws, clock, dev = scada
    ctl.safety.wind = WindState(False, True, "anemometer silent for 75 s")  # on_silence = ignore
    bridge.publish(run(ctl.cycle()))
    wx = dev.models[WEATHER_MODEL_ID][0]
    wx.read()
    assert wx.Stow.value == 0 and wx.Alm.value == 0b00010  # AnemometerLost, no stow


def test_the_anemometer_readings_between_cycles_reach_scada(default_plant):
    """The loop polls the anemometer every [wind] poll_s between cycles; a live run of
    config/hil-storm.toml (5-s polls, 60-s cycles) served WindSpd/WindGst/WindAvg as
    unimplemented for the first minute, then a minute old, and a gust's wind stow beside
    the gust before it.  docs/sunspec.md: the anemometer's last valid reading."""
    _run, ctl, _fws, clock, cfg = default_plant
    wind = WindConfig(link="rs485-1", device_id=11, gust_stow_m_s=20, mean_stow_m_s=14, poll_s=5)
    ctl.safety = SafetyState(wind, cfg.stow, clock.now())
    bridge = Northbound(ctl, "wx-plant")
    assert bridge.snapshot().weather.gust_m_s is None
    t = clock.now()
    ctl.safety.update_wind(t + 5, WindSample(t + 5, 6.0, 9.5, 5.0))
    w = bridge.snapshot().weather
    assert (w.speed_m_s, w.gust_m_s, w.mean_10min_m_s, w.stow) == (6.0, 9.5, 5.0, "")
    assert bridge.snapshot() is bridge.snapshot()  # the same object until the next poll
    ctl.safety.update_wind(t + 10, WindSample(t + 10, 17.0, 24.0, 12.0))
    w = bridge.snapshot().weather
    assert (w.stow, w.gust_m_s) == ("wind", 24.0) and "gust 24.0" in w.reason
