"""Register map, encoding and config: no sockets."""

from __future__ import annotations

import json
from datetime import datetime
from importlib import resources

import pytest

from controller.errors import ConfigError
from controller.schema import load
from controller.sunspec import PlantSnapshot, SunSpecConfig, SunSpecMap, TrackerSnapshot
from controller.sunspec.control import ControlTable, WriteRefused
from controller.sunspec.encode import Encoder, decode_point, deg_to_raw, encode_point, raw_to_deg
from controller.sunspec.vendor import WEATHER_MODEL_ID, weather_model_definition


def _plant(n, kind="dual-axis", **kw):
    trs = [TrackerSnapshot(f"T{i}", 30.0 + i, 170.0 + i, 29.5 + i, 171.0 + i) for i in range(n)]
    return PlantSnapshot("p", kind, datetime(2026, 3, 20, 12, 0, 0), trs, **kw)


def _json_sizes(model_id):
    path = resources.files("sunspec2") / "models" / "json" / f"model_{model_id}.json"
    return json.loads(path.read_text())


@pytest.mark.parametrize("n", [0, 1, 2, 5, 1000])
def test_model_601_length_is_26_plus_22n(n):
    m = SunSpecMap(n)
    assert m.tracker_model_length == 26 + 22 * n
    assert m.common_length == 66
    assert m.common_address == 40002
    assert m.tracker_model_address == 40070
    assert m.weather_model_address == 40070 + 2 + 26 + 22 * n  # vendor model 64601 follows
    assert m.weather_model_length == 24
    assert m.end_address == m.weather_model_address + 2 + 24


def test_offsets_follow_the_json():
    d = _json_sizes(601)
    m = SunSpecMap(3)
    addr = m.tracker_model_address
    for p in d["group"]["points"]:
        assert m.slot(p["name"]).address == addr
        addr += p["size"]
    for i in range(3):
        for p in d["group"]["groups"][0]["points"]:
            assert m.slot(p["name"], i).address == addr
            addr += p["size"]
    assert addr == m.weather_model_address
    for p in weather_model_definition()["group"]["points"]:
        assert m.slot(p["name"], model=WEATHER_MODEL_ID).address == addr
        addr += p["size"]
    assert addr == m.end_address


def test_too_many_trackers_is_refused():
    with pytest.raises(ValueError, match="at most"):
        SunSpecMap(5000)


def test_scaling_round_trip_and_sentinels():
    assert deg_to_raw(12.3456) == 12346
    assert raw_to_deg(33300) == 33.3
    assert deg_to_raw(None) == -(2**31) and raw_to_deg(-(2**31)) is None
    assert deg_to_raw(float("nan")) == -(2**31)


def test_encoder_marker_and_end_model():
    m = SunSpecMap(2)
    plant = _plant(2)
    ct = ControlTable(m)
    ct.refresh(plant)
    regs = Encoder(m).registers(plant, ct.staged, m.base_address, m.size)
    assert regs[0:2] == [0x5375, 0x6E53]
    assert regs[-2:] == [0xFFFF, 0]
    el = m.slot("ElPos", 1)
    off = el.address - m.base_address
    assert raw_to_deg(decode_point(el.point, regs[off : off + 2])) == pytest.approx(30.5)


def test_partial_range_matches_full_render():
    m = SunSpecMap(4)
    plant = _plant(4)
    ct = ControlTable(m)
    ct.refresh(plant)
    enc = Encoder(m)
    full = enc.registers(plant, ct.staged, m.base_address, m.size)
    for start in (40000, 40001, 40071, 40100, 40121, 40150):
        for count in (1, 3, 7, 40):
            count = min(count, m.base_address + m.size - start)
            assert (
                enc.registers(plant, ct.staged, start, count)
                == full[start - m.base_address : start - m.base_address + count]
            )


def test_single_axis_typ_and_rotation_in_elevation():
    m = SunSpecMap(1)
    plant = PlantSnapshot(
        "row", "single-axis", datetime(2026, 3, 20), [TrackerSnapshot.row("R0", -25.0, -24.5)]
    )
    ct = ControlTable(m)
    ct.refresh(plant)
    enc = Encoder(m)
    typ = m.slot("Typ")
    assert enc.registers(plant, ct.staged, typ.address, 1) == [typ.point.symbol_value("Horizontal")]
    tilted = PlantSnapshot(
        "row",
        "single-axis",
        datetime(2026, 3, 20),
        [TrackerSnapshot.row("R0", -25.0, -24.5)],
        axis_tilt_deg=5.0,
    )
    assert enc.registers(tilted, ct.staged, typ.address, 1) == [typ.point.symbol_value("Tilted")]
    el, az = m.slot("ElPos", 0), m.slot("AzPos", 0)
    assert raw_to_deg(decode_point(el.point, enc.registers(plant, ct.staged, el.address, 2))) == -24.5
    assert raw_to_deg(decode_point(az.point, enc.registers(plant, ct.staged, az.address, 2))) is None


def test_a_row_of_a_mixed_plant_reads_its_azimuth_points_as_unimplemented():
    # a live audit on config/hil-default.toml (a dual-axis tracker and a row): after a
    # global Manual with GlblAzCtl = 200, the row's AzCtl read 200.0 beside its
    # unimplemented AzTrgt and AzPos; the row has no azimuth, and its AzCtl refuses writes
    m = SunSpecMap(2)
    plant = PlantSnapshot(
        "mixed",
        "dual-axis",
        datetime(2026, 3, 20),
        [TrackerSnapshot("D0", 30.0, 170.0, 29.5, 171.0), TrackerSnapshot.row("R0", -25.0, -24.5)],
    )
    ct = ControlTable(m)
    ct.refresh(plant)
    g_el = m.slot("GlblElCtl")
    words = encode_point(g_el.point, 20000) + encode_point(g_el.point, 200000) + [1]
    ct.apply_write(plant, g_el.address, words)
    enc = Encoder(m)

    def deg(name, tracker):
        slot = m.slot(name, tracker)
        return raw_to_deg(decode_point(slot.point, enc.registers(plant, ct.staged, slot.address, 2)))

    assert [deg(n, 0) for n in ("AzCtl", "ElCtl")] == [200.0, 20.0]
    assert [deg(n, 1) for n in ("AzTrgt", "AzPos", "AzCtl", "ElCtl")] == [None, None, None, 20.0]


def test_control_write_must_cover_whole_writable_points():
    m = SunSpecMap(2)
    plant = _plant(2)
    ct = ControlTable(m)
    ct.refresh(plant)
    el = m.slot("ElCtl", 0)
    with pytest.raises(WriteRefused) as e:
        ct.apply_write(plant, el.address + 1, [0])  # half an int32
    assert e.value.code == 2
    with pytest.raises(WriteRefused) as e:
        ct.apply_write(plant, m.slot("ElTrgt", 0).address, [0, 1000])
    assert e.value.code == 2
    # ElCtl + AzCtl + Ctl in one request: one command
    words = (
        encode_point(el.point, 45000)
        + encode_point(el.point, 90000)
        + encode_point(m.slot("Ctl", 0).point, 1)
    )
    cmds = ct.apply_write(plant, el.address, words)
    assert [(c.tracker, c.ctl, c.el_deg, c.az_deg) for c in cmds] == [(0, "Manual", 45.0, 90.0)]


def parse_sunspec(doc, file="<config>"):
    return load(SunSpecConfig, doc.get("sunspec", {}), file, "sunspec")


def test_parse_sunspec_defaults_and_values():
    assert parse_sunspec({}) == SunSpecConfig()
    cfg = parse_sunspec(
        {
            "sunspec": {
                "enabled": True,
                "port": 0,
                "writes_enabled": True,
                "allow": ["127.0.0.1", "10.0.0.0/24"],
                "device_address": 3,
            }
        }
    )
    assert cfg.enabled and cfg.port == 0 and cfg.writes_enabled
    assert cfg.allow == ("127.0.0.1", "10.0.0.0/24") and cfg.device_address == 3
    assert cfg.host == "127.0.0.1"


@pytest.mark.parametrize(
    "table, key",
    [
        ({"port": 70000}, "sunspec.port"),
        ({"port": "1502"}, "sunspec.port"),
        ({"host": "scada.example"}, "sunspec.host"),
        ({"allow": ["127.0.0.1", "not-an-ip"]}, "sunspec.allow[1]"),
        ({"allow": "127.0.0.1"}, "sunspec.allow"),
        ({"writes_enabled": "yes"}, "sunspec.writes_enabled"),
        ({"device_address": 0}, "sunspec.device_address"),
        ({"bogus": 1}, "sunspec.bogus"),
    ],
)
def test_parse_sunspec_errors_name_file_and_key(table, key):
    with pytest.raises(ConfigError) as e:
        parse_sunspec({"sunspec": table}, "plant.toml")
    assert e.value.key == key
    assert str(e.value).startswith(f"plant.toml: {key}:")


def test_largest_plant_that_fits_below_65536():
    assert SunSpecMap(1155).end_address + 1 <= 0xFFFF
    with pytest.raises(ValueError, match="at most 1155"):  # 1156 before the vendor model
        SunSpecMap(1156)


@pytest.mark.parametrize(
    "peer, allowed",
    [
        ("127.0.0.1", True),
        ("10.0.0.7", True),
        ("10.0.1.7", False),
        ("::ffff:10.0.0.7", True),
        ("::1", False),
        (None, False),
        ("", False),
        ("garbage", False),
    ],
)
def test_peer_allowlist(peer, allowed):
    from controller.sunspec.server import _networks, peer_allowed

    assert peer_allowed(peer, _networks(["127.0.0.1", "10.0.0.0/24"])) is allowed


def test_tracker_mode_accepts_control_mode_members():
    from controller.modes import ControlMode
    from controller.sunspec.encode import ctl_name_for_mode

    tr = TrackerSnapshot("t", 1.0, 2.0, 1.0, 2.0, ControlMode.MANUAL)
    assert tr.mode == "MANUAL" and ctl_name_for_mode(tr.mode) == "Manual"
    with pytest.raises(ValueError):
        TrackerSnapshot("t", 1.0, 2.0, 1.0, 2.0, "SLEEP")
