"""SunSpec hardening (issue 13): the default binding and write policy, model 601 writes
refused during a weather stow (exception 6), and the weather vendor model 64601 as a SCADA
client built on pysunspec2 sees it: with heliotrack's model definition on its path it
decodes the wind, the stow and the alarms and writes a snow or hail request; without it, it
still scans the device."""

from __future__ import annotations

import socket
import struct
from dataclasses import replace
from datetime import datetime

import pytest
import sunspec2.device as sunspec_device
from pymodbus.client import ModbusTcpClient
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP
from sunspec2.modbus.modbus import ModbusClientError

from controller.sunspec import (
    PlantSnapshot,
    StowRequest,
    SunSpecConfig,
    SunSpecServer,
    TrackerSnapshot,
    WeatherSnapshot,
    write_model_json,
)
from controller.sunspec.control import ControlTable, WriteRefused
from controller.sunspec.models import SunSpecMap
from controller.sunspec.vendor import WEATHER_MODEL_ID
from tests.controller.sunspec.conftest import server_starter

HOST = "127.0.0.1"
STORM = WeatherSnapshot(
    stow="wind",
    reason="wind: gust 24.6 m/s, 10-min mean 15.2 m/s",
    speed_m_s=17.25,
    gust_m_s=24.6,
    mean_10min_m_s=15.2,
    requests=(("flag file", "snow"),),
)


class Plant:
    def __init__(self, weather: WeatherSnapshot | None = None):
        self.weather = weather or WeatherSnapshot()
        self.commands: list = []

    def __call__(self) -> PlantSnapshot:
        trackers = [
            TrackerSnapshot(f"t{i}", 30.0, 180.0, 30.0, 180.0, el_limits_deg=(0.0, 90.0)) for i in range(2)
        ]
        return PlantSnapshot("wx", "dual-axis", datetime(2026, 1, 5, 9, 0), trackers, weather=self.weather)

    def on_override(self, cmd) -> None:
        self.commands.append(cmd)


@pytest.fixture
def serve():
    """SunSpec servers with SCADA's writes on unless a test says otherwise."""
    start, servers = server_starter(writes_enabled=True)
    yield start
    for srv in servers:
        srv.stop()


@pytest.fixture
def model_path(tmp_path):
    """pysunspec2 with heliotrack's model 64601 on its model path (restored afterwards)."""
    before = list(sunspec_device.get_model_defs_path())
    write_model_json(tmp_path)
    sunspec_device.set_model_defs_path([str(tmp_path), *before])
    yield tmp_path
    sunspec_device.set_model_defs_path(before)


def scan(srv) -> SunSpecModbusClientDeviceTCP:
    dev = SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr=HOST, ipport=srv.port, timeout=2)
    dev.scan()
    return dev


def exception_code(exc: BaseException) -> int:
    import re

    found = re.search(r"Modbus exception:? (\d+)", str(exc))
    assert found, str(exc)
    return int(found.group(1))


def listening_addresses(port: int) -> set[str]:
    """Local addresses with a TCP socket listening on ``port`` (from /proc/net/tcp)."""
    out = set()
    with open("/proc/net/tcp") as f:
        for line in f.readlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, p = local.split(":")
            if int(p, 16) == port and state == "0A":
                out.add(socket.inet_ntoa(struct.pack("<I", int(addr, 16))))
    return out


def test_the_defaults_bind_to_loopback_and_refuse_every_write():
    cfg = replace(SunSpecConfig(), port=0)
    assert (cfg.host, cfg.writes_enabled, cfg.allow) == ("127.0.0.1", False, ("127.0.0.1",))
    plant = Plant()
    with SunSpecServer.from_config(cfg, plant, plant.on_override) as srv:
        assert listening_addresses(srv.port) == {"127.0.0.1"}
        client = ModbusTcpClient(HOST, port=srv.port, timeout=2)
        assert client.connect()
        try:
            ctl = srv.map.slot("Ctl", 0)
            rr = client.write_register(ctl.address, 1, device_id=1)
            assert rr.isError() and rr.exception_code == 1
            stow_req = srv.map.slot("StowReq", model=WEATHER_MODEL_ID)
            rr = client.write_register(stow_req.address, 1, device_id=1)
            assert rr.isError() and rr.exception_code == 1
        finally:
            client.close()
    assert plant.commands == []


def test_model_601_writes_are_refused_during_a_weather_stow():
    table = ControlTable(SunSpecMap(2))
    calm, storm = Plant()(), replace(Plant()(), weather=STORM)
    ctl = table.map.slot("Ctl", 1)
    with pytest.raises(WriteRefused) as e:
        table.apply_write(storm, ctl.address, [1])
    assert int(e.value.code) == 6 and "gust 24.6" in e.value.reason
    assert table.staged[1].ctl == "Automatic"  # nothing staged
    assert table.apply_write(calm, ctl.address, [1])[0].ctl == "Manual"
    # a value that can never be right is still exception 3 (retrying later would not help)
    with pytest.raises(WriteRefused) as e:
        table.apply_write(storm, ctl.address, [7])
    assert int(e.value.code) == 3


@pytest.mark.parametrize("stow", ["wind", "hail", "snow"])
def test_scada_gets_device_busy_for_an_override_in_any_weather_stow(serve, stow):
    plant = Plant(WeatherSnapshot(stow=stow, reason=f"{stow} stow"))
    srv = serve(plant)
    dev = scan(srv)
    try:
        blk = dev.models[601][0].tracker[0]
        blk.ElCtl.cvalue = 20.0
        blk.Ctl.value = 1
        with pytest.raises(ModbusClientError) as e:
            blk.write()
        assert exception_code(e.value) == 6
        assert plant.commands == [] and srv.stats["writes_refused"] == 1
        plant.weather = WeatherSnapshot()  # the stow is over: the same write goes through
        blk.ElCtl.cvalue = 20.0
        blk.Ctl.value = 1
        blk.write()
        assert plant.commands[-1].ctl == "Manual" and plant.commands[-1].el_deg == 20.0
    finally:
        dev.close()


def test_pysunspec2_with_the_model_file_reads_the_weather_and_requests_a_stow(serve, model_path):
    plant = Plant(STORM)
    srv = serve(plant)
    dev = scan(srv)
    try:
        assert sorted(k for k in dev.models if isinstance(k, int)) == [1, 601, WEATHER_MODEL_ID]
        wx = dev.models[WEATHER_MODEL_ID][0]
        assert not wx.error_info
        assert wx.L.value == 24 and wx.Wind_SF.value == -2
        assert wx.Stow.value == 1  # WIND
        assert (wx.WindSpd.cvalue, wx.WindGst.cvalue, wx.WindAvg.cvalue) == (17.25, 24.6, 15.2)
        assert wx.Alm.value == 0b01001  # WindStow, SnowStow (the flag file's, outranked)
        assert wx.Rsn.value == STORM.reason[:32]
        assert wx.StowReq.value == 0
        # SCADA asks for a hail stow: allowed during the wind stow (it is not an override)
        wx.StowReq.value = 2
        wx.write()
        assert plant.commands == [StowRequest("hail", "127.0.0.1")]
        wx.read()
        assert wx.StowReq.value == 2  # staged until the controller publishes it
        with pytest.raises(ModbusClientError) as e:
            wx.StowReq.value = 3
            wx.write()
        assert exception_code(e.value) == 3
        # read-only vendor points
        client = ModbusTcpClient(HOST, port=srv.port, timeout=2)
        assert client.connect()
        try:
            rr = client.write_register(srv.map.slot("Stow", model=WEATHER_MODEL_ID).address, 0, device_id=1)
            assert rr.isError() and rr.exception_code == 2
        finally:
            client.close()
    finally:
        dev.close()


def test_pysunspec2_without_the_model_file_still_scans_the_device(serve):
    srv = serve(Plant(STORM))
    dev = scan(srv)
    try:
        assert sorted(k for k in dev.models if isinstance(k, int)) == [1, 601, WEATHER_MODEL_ID]
        m = dev.models[601][0]
        assert m.N.value == 2 and m.tracker[1].ElPos.cvalue == 30.0  # the standard models read
        assert "not found" in dev.models[WEATHER_MODEL_ID][0].error_info
    finally:
        dev.close()


def test_no_anemometer_reads_as_unimplemented(serve, model_path):
    srv = serve(Plant(WeatherSnapshot()))
    dev = scan(srv)
    try:
        wx = dev.models[WEATHER_MODEL_ID][0]
        assert (wx.WindSpd.value, wx.WindGst.value, wx.WindAvg.value) == (None, None, None)
        assert (wx.Stow.value, wx.Alm.value, wx.Rsn.value) == (0, 0, None)
    finally:
        dev.close()
