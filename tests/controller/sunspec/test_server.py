"""The northbound server as a SCADA client sees it: pysunspec2 over TCP on 127.0.0.1."""

from __future__ import annotations

import re
import threading
from contextlib import closing
from datetime import datetime

import pytest
from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP, SunSpecModbusClientError
from sunspec2.modbus.modbus import ModbusClientError

from controller.sunspec import PlantSnapshot, SunSpecServer, TrackerSnapshot
from heliotrack.sunspec_latency import poll_latency

HOST = "127.0.0.1"  # never anything else in tests


class Plant:
    """A mutable plant the tests change between reads (the server re-reads it)."""

    def __init__(self, n: int, kind: str = "dual-axis", **tracker_kw):
        self.lock = threading.Lock()
        self.kind = kind
        self.trackers = [self._tracker(i, **tracker_kw) for i in range(n)]
        self.overrides = []

    def _tracker(self, i, **kw):
        if self.kind == "single-axis":
            return TrackerSnapshot.row(
                f"row-{i}", -40.0 + 7.25 * i, -39.871 + 7.25 * i, alarm_bits=i % 8, **kw
            )
        return TrackerSnapshot(
            f"trk-{i:02d}",
            10.0 + 11.125 * i,
            95.5 + 23.001 * i,
            9.999 + 11.125 * i,
            96.0 + 23.0 * i,
            "TRACK",
            i % 8,
            **kw,
        )

    def __call__(self) -> PlantSnapshot:
        with self.lock:
            return PlantSnapshot(
                "heliotrack-test", self.kind, datetime(2026, 6, 21, 14, 3, 7), list(self.trackers)
            )

    def on_override(self, cmd):
        self.overrides.append(cmd)


def scan(srv, slave_id=1) -> SunSpecModbusClientDeviceTCP:
    dev = SunSpecModbusClientDeviceTCP(slave_id=slave_id, ipaddr=HOST, ipport=srv.port, timeout=2)
    dev.scan()
    return dev


def model_ids(dev):
    return sorted(k for k in dev.models if isinstance(k, int))


@pytest.mark.parametrize("n", [2, 5])
def test_pysunspec2_scans_and_reads_every_tracker_with_scale_factor(serve, n):
    plant = Plant(n)
    srv = serve(plant)
    dev = scan(srv)
    try:
        assert model_ids(dev) == [1, 601, 64601]  # 64601: heliotrack's weather model
        common = dev.common[0]
        assert common.Mn.value == "heliotrack"
        assert common.Vr.value
        m = dev.models[601][0]
        assert m.ID.value == 601 and m.L.value == 26 + 22 * n
        assert m.N.value == n and m.Dgr_SF.value == -3
        assert m.Nam.value == "heliotrack-test"
        assert m.Typ.value == 5  # Dual
        assert (m.DtLoc.value, m.TmLoc.value, m.Day.value) == ("20260621", "140307", 172)
        assert m.GlblCtl.value == 0
        assert len(m.tracker) == n
        glbl_alm = 0
        for i, tr in enumerate(plant.trackers):
            blk = m.tracker[i]
            assert blk.Id.value == tr.name
            assert blk.ElTrgt.cvalue == pytest.approx(tr.el_target_deg, abs=5e-4)
            assert blk.AzTrgt.cvalue == pytest.approx(tr.az_target_deg, abs=5e-4)
            assert blk.ElPos.cvalue == pytest.approx(tr.el_pos_deg, abs=5e-4)
            assert blk.AzPos.cvalue == pytest.approx(tr.az_pos_deg, abs=5e-4)
            # the raw value really is milli-degrees (the client applied SF = -3)
            assert blk.AzTrgt.value == round(tr.az_target_deg * 1000)
            assert blk.ElCtl.value is None and blk.AzCtl.value is None
            assert blk.Ctl.value == 0 and blk.Alm.value == tr.alarm_bits
            glbl_alm |= tr.alarm_bits
        assert m.GlblAlm.value == glbl_alm
    finally:
        dev.close()


def test_reads_follow_the_snapshot(serve):
    plant = Plant(2)
    srv = serve(plant)
    dev = scan(srv)
    try:
        m = dev.models[601][0]
        with plant.lock:
            plant.trackers[1] = TrackerSnapshot(
                "trk-01", 50.0, 200.0, 49.0, 201.0, "MANUAL", 0, manual_el_deg=49.0, manual_az_deg=201.0
            )
        m.read()
        blk = m.tracker[1]
        assert (blk.ElPos.cvalue, blk.Ctl.value, blk.ElCtl.cvalue) == (49.0, 1, 49.0)
        assert m.tracker[0].Ctl.value == 0
    finally:
        dev.close()


def test_single_axis_rotation_is_served_in_elevation_points(serve):
    plant = Plant(3, "single-axis")
    srv = serve(plant)
    dev = scan(srv)
    try:
        m = dev.models[601][0]
        assert m.Typ.value == 2  # Horizontal
        for i, tr in enumerate(plant.trackers):
            blk = m.tracker[i]
            assert blk.ElPos.cvalue == pytest.approx(tr.el_pos_deg, abs=5e-4)
            assert blk.ElTrgt.cvalue == pytest.approx(tr.el_target_deg, abs=5e-4)
            assert blk.AzPos.value is None and blk.AzTrgt.value is None
    finally:
        dev.close()


def _write(dev, tracker_no, **points):
    """Set points of repeating block ``tracker_no`` (0-based) and write them."""
    m = dev.models[601][0]
    blk = m.tracker[tracker_no]
    for name, value in points.items():
        pt = getattr(blk, name)
        if name == "Ctl":
            pt.value = value
        else:
            pt.cvalue = value
    blk.write()


def _refused_with(exc_info, code):
    # pysunspec2 words it "Modbus exception 2: addr..." for reads, "Modbus exception: 2" for writes
    found = re.search(r"Modbus exception:? (\d+)", str(exc_info.value))
    assert found and int(found.group(1)) == code, str(exc_info.value)


def test_writes_refused_when_disabled(serve):
    plant = Plant(2)
    srv = serve(plant, allow=[HOST])  # allowlisted, but writes not enabled
    dev = scan(srv)
    try:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 0, ElCtl=30.0)
        _refused_with(e, 1)
        with pytest.raises(ModbusClientError):
            _write(dev, 1, Ctl=1)
        m = dev.models[601][0]
        m.read()
        assert m.tracker[0].ElCtl.value is None and m.tracker[1].Ctl.value == 0
        assert plant.overrides == []
        assert srv.stats["writes_refused"] == 2 and srv.stats["writes_accepted"] == 0
    finally:
        dev.close()


def test_writes_refused_from_a_client_not_in_the_allowlist(serve):
    plant = Plant(2)
    srv = serve(plant, writes_enabled=True, allow=["10.11.12.13", "192.168.0.0/16"])
    dev = scan(srv)
    try:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 0, ElCtl=30.0, AzCtl=120.0, Ctl=1)
        _refused_with(e, 1)
        m = dev.models[601][0]
        m.read()
        assert m.tracker[0].Ctl.value == 0 and m.tracker[0].ElCtl.value is None
        assert plant.overrides == []
    finally:
        dev.close()


def test_writes_accepted_and_delivered_when_enabled_and_allowlisted(serve):
    plant = Plant(5)
    srv = serve(plant, writes_enabled=True, allow=["127.0.0.0/8"])
    dev = scan(srv)
    try:
        # contiguous ElCtl, AzCtl, Ctl: pysunspec2 sends them as one FC16 write
        _write(dev, 2, ElCtl=35.125, AzCtl=210.5, Ctl=1)
        assert len(plant.overrides) == 1
        cmd = plant.overrides[-1]
        assert (cmd.tracker, cmd.ctl, cmd.el_deg, cmd.az_deg, cmd.peer) == (
            2,
            "Manual",
            35.125,
            210.5,
            "127.0.0.1",
        )
        # a later write of one point carries the staged rest of the scope
        _write(dev, 2, ElCtl=20.0)
        assert (plant.overrides[-1].ctl, plant.overrides[-1].el_deg, plant.overrides[-1].az_deg) == (
            "Manual",
            20.0,
            210.5,
        )
        m = dev.models[601][0]
        m.read()
        blk = m.tracker[2]
        assert (blk.Ctl.value, blk.ElCtl.cvalue, blk.AzCtl.cvalue) == (1, 20.0, 210.5)
        # global: stow-like manual position for every tracker, then back to automatic
        m.GlblElCtl.cvalue = 0.0
        m.GlblAzCtl.cvalue = 180.0
        m.GlblCtl.value = 1
        m.write()
        glbl = [c for c in plant.overrides if c.tracker is None]
        assert (glbl[-1].ctl, glbl[-1].el_deg, glbl[-1].az_deg) == ("Manual", 0.0, 180.0)
        m.read()
        assert all(m.tracker[i].Ctl.value == 1 for i in range(5))
        m.GlblCtl.value = 0
        m.write()
        assert plant.overrides[-1].tracker is None and plant.overrides[-1].ctl == "Automatic"
        assert srv.stats["writes_refused"] == 0
    finally:
        dev.close()


@pytest.mark.parametrize(
    "points, code",
    [
        ({"ElCtl": 90.5}, 3),  # above the horizon range
        ({"ElCtl": -91.0}, 3),
        ({"AzCtl": 360.0}, 3),  # azimuth in [0, 360)
        ({"AzCtl": -0.5}, 3),
        ({"ElCtl": 85.0}, 3),  # inside the protocol range, outside this tracker's limits
        ({"Ctl": 3}, 3),  # model 601 Ctl has no value 3
        ({"ElTrgt": 40.0}, 2),  # read-only point
        ({"Alm": 0}, 2),
    ],
)
def test_invalid_writes_refused(serve, points, code):
    plant = Plant(2, el_limits_deg=(5.0, 80.0))
    srv = serve(plant, writes_enabled=True)
    dev = scan(srv)
    try:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 1, **points)
        _refused_with(e, code)
        m = dev.models[601][0]
        m.read()
        assert m.tracker[1].ElCtl.value is None and m.tracker[1].Ctl.value == 0
        assert plant.overrides == []
    finally:
        dev.close()


def test_single_axis_refuses_azimuth_writes_and_takes_rotation(serve):
    plant = Plant(2, "single-axis", rotation_limits_deg=(-55.0, 55.0))
    srv = serve(plant, writes_enabled=True)
    dev = scan(srv)
    try:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 0, AzCtl=90.0)
        _refused_with(e, 2)
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 0, ElCtl=-60.0)
        _refused_with(e, 3)
        _write(dev, 0, ElCtl=-30.0, Ctl=1)
        assert [(c.tracker, c.ctl, c.el_deg, c.az_deg) for c in plant.overrides][-1] == (
            0,
            "Manual",
            -30.0,
            None,
        )
    finally:
        dev.close()


def test_a_row_of_a_mixed_plant_refuses_azimuth_writes(serve):
    """An audit's case: the plant's Typ is the dual-axis one, and a row's AzCtl = 100 deg
    was accepted (and ignored); docs/sunspec.md says exception 2."""
    plant = Plant(1)
    plant.trackers.append(TrackerSnapshot.row("row-1", -40.0, -39.9, rotation_limits_deg=(-55.0, 55.0)))
    with closing(scan(serve(plant, writes_enabled=True))) as dev:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 1, AzCtl=100.0)
        _refused_with(e, 2)
        _write(dev, 0, AzCtl=100.0, ElCtl=30.0, Ctl=1)  # the dual-axis tracker's are writable
    assert [(c.tracker, c.az_deg) for c in plant.overrides][-1] == (0, 100.0)


def test_failing_override_callback_refuses_and_unstages(serve):
    plant = Plant(1)

    def boom(cmd):
        raise RuntimeError("controller busy")

    plant.on_override = boom
    srv = serve(plant, writes_enabled=True)
    dev = scan(srv)
    try:
        with pytest.raises(ModbusClientError) as e:
            _write(dev, 0, ElCtl=30.0, Ctl=1)
        _refused_with(e, 4)
        m = dev.models[601][0]
        m.read()
        assert m.tracker[0].Ctl.value == 0 and m.tracker[0].ElCtl.value is None
    finally:
        dev.close()


def test_other_unit_ids_are_not_answered_as_ours(serve):
    srv = serve(Plant(1))
    dev = SunSpecModbusClientDeviceTCP(slave_id=7, ipaddr=HOST, ipport=srv.port, timeout=1)
    with pytest.raises(SunSpecModbusClientError):
        dev.scan()
    dev.close()


def test_poll_latency_reports_figures(serve):
    srv = serve(Plant(5))
    res = poll_latency(HOST, srv.port, 10)
    assert res.n_trackers == 5 and res.registers == 2 + 26 + 22 * 5 and res.n == 10
    assert 0 < res.read_p50_s <= res.read_p99_s <= res.read_max_s
    assert "p99" in res.summary()


@pytest.mark.parametrize(("enabled", "code"), [(False, 1), (True, 2)])
def test_a_write_outside_the_map_is_answered_by_policy_and_logged(serve, caplog, enabled, code):
    """An audit's case: a write past the end got exception 2 even with writes disabled (a
    refused client could map the registers), and no log line."""
    from pymodbus.client import ModbusTcpClient

    srv = serve(Plant(1), writes_enabled=enabled, allow=[HOST])
    client = ModbusTcpClient(HOST, port=srv.port)
    assert client.connect()
    try:
        past = 40000 + srv.map.size + 10
        reply = client.write_register(past, 1, device_id=1)
        assert reply.isError() and reply.exception_code == code
    finally:
        client.close()
    assert f"SunSpec write at {past} from 127.0.0.1 refused (exception {code})" in caplog.text


def test_a_client_that_writes_in_a_loop_does_not_fill_the_log(serve, caplog):
    """An audit's case: 1000 writes in 0.15 s were 1000 log lines."""
    from pymodbus.client import ModbusTcpClient

    srv = serve(Plant(1), writes_enabled=False, allow=[HOST])
    client = ModbusTcpClient(HOST, port=srv.port)
    assert client.connect()
    try:
        for _ in range(200):
            assert client.write_register(40002, 1, device_id=1).exception_code == 1
    finally:
        client.close()
    assert srv.stats["writes_refused"] == 200  # every one counted and answered
    assert caplog.text.count("refused (exception 1)") == 20
    srv._log_budget._open = {k: (v[0] - 60.0, v[1], v[2]) for k, v in srv._log_budget._open.items()}
    assert srv._log_budget.allows(HOST)  # the next window opens with the count of the rest
    assert "SunSpec: 180 more writes from 127.0.0.1 in 10 s were not logged" in caplog.text


def test_a_port_in_use_is_named_as_such():
    """A walk of docs/deploy.md: a second ``run`` (or ``simulate --realtime``) on the
    plant's SunSpec port said only pymodbus's "Could not start listen, please check
    address." for an address that was right."""
    import socket

    from controller.sunspec.server import SunSpecServerError

    with socket.socket() as busy:
        busy.bind((HOST, 0))
        busy.listen()
        port = busy.getsockname()[1]
        plant = Plant(1)
        with pytest.raises(SunSpecServerError, match=f"{HOST}:{port}: the port is in use by another program"):
            SunSpecServer(plant, plant.on_override, host=HOST, port=port).start().stop()
