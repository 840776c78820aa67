"""`simulate` emulates every link kind from TOML alone: CANopen (config/hil-canopen.toml)
and a plant on RS-485, Modbus TCP and CAN at once with the pyranometer behind the TCP
gateway (config/hil-mixed.toml)."""

import json

import pytest

from heliotrack.cli import main
from tests.conftest import DEFAULT_CONFIG, REPO

CANOPEN = REPO / "config" / "hil-canopen.toml"
MIXED = REPO / "config" / "hil-mixed.toml"
MORNING = "2024-03-20T05:00:00+00:00"  # 08:13 local mean time at the site


def simulate(tmp_path, config, start=MORNING, hours=2.0, name="out") -> dict:
    out = tmp_path / name
    assert (
        main(
            [
                "simulate",
                "--config",
                str(config),
                "--start",
                start,
                "--hours",
                str(hours),
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    return json.loads((out / "summary.json").read_text())


@pytest.fixture(scope="module")
def rtu_reference(tmp_path_factory):
    """The default scenario (one RS-485 line) over the same hours."""
    return simulate(tmp_path_factory.mktemp("rtu"), DEFAULT_CONFIG)


def assert_clean(summary: dict) -> None:
    assert all(t["errors"] == 0 for t in summary["trackers"].values()), summary["trackers"]
    assert all(link["errors"] == 0 and link["transactions"] > 0 for link in summary["links"].values()), (
        summary["links"]
    )
    assert summary["modbus"]["errors"] == summary["modbus"]["sensor_errors"] == 0


def assert_like_rtu(summary: dict, rtu: dict) -> None:
    """Each tracker points as well as the same kind of tracker on the RS-485 line."""
    for name, t in summary["trackers"].items():
        twin = rtu["trackers"]["dual-1" if name.startswith("dual") else "row-1"]
        assert t["pointing_error_deg"]["p95"] == pytest.approx(twin["pointing_error_deg"]["p95"], abs=0.01), (
            name
        )


def test_canopen_plant_from_toml(tmp_path, rtu_reference):
    s = simulate(tmp_path, CANOPEN)
    assert s["links"].keys() == {"can-1"} and s["links"]["can-1"]["kind"] == "canopen"
    assert set(s["trackers"]) == {"dual-1", "row-1", "row-2", "row-3"}
    assert s["modes"] == {"TRACK": 4 * 120}
    assert_clean(s)
    assert_like_rtu(s, rtu_reference)


def test_mixed_plant_from_toml(tmp_path, rtu_reference):
    s = simulate(tmp_path, MIXED)
    assert {name: link["kind"] for name, link in s["links"].items()} == {
        "rs485-1": "modbus-rtu",
        "tcp-1": "modbus-tcp",
        "can-1": "canopen",
    }
    assert {t["link"] for t in s["trackers"].values()} == {"rs485-1", "tcp-1", "can-1"}
    assert s["modes"] == {"TRACK": 7 * 120}
    assert_clean(s)
    assert_like_rtu(s, rtu_reference)


def test_pyranometer_behind_the_tcp_gateway_drives_diffuse(tmp_path):
    # Overcast from before sunrise: DIFFUSE once two hours of it were seen with the sun
    # above 10 deg, which takes the pyranometer's every reading over Modbus TCP.
    cfg = tmp_path / "mixed-overcast.toml"
    cfg.write_text(MIXED.read_text().replace('sky = "clear"', 'sky = "overcast"'))
    s = simulate(tmp_path, cfg, start="2024-03-20T03:00:00+00:00", hours=4.0)
    assert s["modbus"]["sensor_errors"] == 0
    assert s["modes"].get("DIFFUSE", 0) > 0, s["modes"]
    assert_clean(s)


def test_rtu_line_settings_are_emulated_as_configured(tmp_path):
    # Linux refuses a parity bit on a pty: the world hands the controller the pty's slave
    # end by ptyfd://, and the client still opens with the link's own settings.
    cfg = tmp_path / "even-parity.toml"
    cfg.write_text(
        DEFAULT_CONFIG.read_text().replace(
            "baudrate = 115200", 'baudrate = 19200\nparity = "E"\nstopbits = 2'
        )
    )
    s = simulate(tmp_path, cfg, hours=0.5)
    assert s["modes"] == {"TRACK": 2 * 30}
    assert_clean(s)
