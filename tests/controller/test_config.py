import pytest

from controller.config import Config, SingleAxisTracker, load_config, parse_config
from controller.drives.links import CanopenLink, ModbusRtuLink, ModbusTcpLink
from controller.errors import ConfigError
from heliotrack.scenario import load_scenario
from tests.conftest import DEFAULT_CONFIG


def test_default_config_loads():
    cfg = load_scenario(DEFAULT_CONFIG)
    assert cfg.site.latitude == pytest.approx(32.4835)
    assert [t.type for t in cfg.trackers] == ["dual-axis", "single-axis"]
    assert cfg.control.heartbeat_timeout_s > cfg.control.period_s
    assert cfg.control.lead_s == 30.0 and cfg.control.heartbeat_timeout_s == 180.0
    assert cfg.diffuse.enabled is True and cfg.file == str(DEFAULT_CONFIG)
    row = cfg.trackers[1]
    assert isinstance(row, SingleAxisTracker) and row.stow_angles == (0.0,)


def test_a_plant_config_has_no_hil_table():
    with pytest.raises(ConfigError, match=r"hil: expected one of the known keys"):
        load_config(DEFAULT_CONFIG)


def write(tmp_path, text):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    return p


BASE = """
[site]
latitude = 10
longitude = 20
[[links]]
name = "a"
kind = "modbus-rtu"
[[trackers]]
name = "t"
type = "dual-axis"
link = "a"
device_id = 1
"""

ROW = '[[trackers]]\nname = "r"\ntype = "single-axis"\nlink = "a"\ndevice_id = 2\n'


@pytest.mark.parametrize(
    "mutate, key, expected",
    [
        (lambda s: s.replace("latitude = 10", "latitude = 100"), "site.latitude", "[-90, 90]"),
        (lambda s: s.replace("latitude = 10", 'latitude = "north"'), "site.latitude", "a number"),
        (lambda s: s.replace('link = "a"', 'link = "b"'), "trackers[0].link", "[[links]]"),
        (lambda s: s.replace("device_id = 1", "device_id = 300"), "trackers[0].device_id", "[1, 247]"),
        (lambda s: s.replace('type = "dual-axis"', 'type = "tri-axis"'), "trackers[0].type", "dual-axis"),
        (
            lambda s: s + "[control]\nperiod_s = 60\nheartbeat_timeout_s = 30\n",
            "control.heartbeat_timeout_s",
            "more than",
        ),
        (lambda s: s + "[control]\nperiod = 60\n", "control.period", "known keys"),
        (lambda s: s.replace("[site]\nlatitude = 10\n", "[site]\n"), "site.latitude", "missing"),
        (lambda s: s + '[hotspot]\ncalibration = "b.toml"\n', "hotspot.calibration", "an existing file"),
        # typos are errors, never silently dropped
        (lambda s: s.replace("[[trackers]]", "[[trackersX]]"), "trackersX", "known keys"),
        (lambda s: s + ROW + "max_angel = 50\n", "trackers[1].max_angel", "known keys"),
        (lambda s: s + "[control]\nstow_wind_speed = 20\n", "control.stow_wind_speed", "known keys"),
        # keys of the other tracker type or link kind
        (lambda s: s.replace("device_id = 1", "device_id = 1\ngcr = 0.3"), "trackers[0].gcr", "known keys"),
        (
            lambda s: s.replace('kind = "modbus-rtu"', 'kind = "modbus-rtu"\ntcp_port = 502'),
            "links[0].tcp_port",
            "known keys",
        ),
        (lambda s: s.replace('kind = "modbus-rtu"', 'kind = "profibus"'), "links[0].kind", "canopen"),
        (
            lambda s: s.replace('kind = "modbus-rtu"', 'kind = "modbus-rtu"\nparity = "X"'),
            "links[0].parity",
            'one of "N", "E", "O"',
        ),
        # stow angles within the axis limits, limits in order
        (
            lambda s: s.replace("device_id = 1", "device_id = 1\nstow = [180.0, 95.0]"),
            "trackers[0].stow[1]",
            "within the axis limits [0, 90]",
        ),
        (lambda s: s + ROW + "max_angle = 45\nstow = 50\n", "trackers[1].stow", "[-45, 45]"),
        (
            lambda s: s.replace("device_id = 1", "device_id = 1\nelevation_limits = [60, 10]"),
            "trackers[0].elevation_limits",
            "min < max",
        ),
    ],
)
def test_errors_name_file_key_and_expectation(tmp_path, mutate, key, expected):
    (tmp_path / "exists.toml").write_text("")
    path = write(tmp_path, mutate(BASE))
    with pytest.raises(ConfigError) as e:
        load_config(path)
    msg = str(e.value)
    assert str(path) in msg and key in msg and expected in msg, msg


def test_every_link_kind_from_toml():
    cfg = parse_config(
        {
            "site": {"latitude": 10, "longitude": 20},
            "links": [
                {
                    "name": "rs485",
                    "kind": "modbus-rtu",
                    "port": "/dev/ttyUSB0",
                    "baudrate": 19200,
                    "parity": "E",
                    "stopbits": 1,
                },
                {"name": "lan", "kind": "modbus-tcp", "host": "10.0.0.7", "tcp_port": 1502},
                {
                    "name": "can",
                    "kind": "canopen",
                    "interface": "slcan",
                    "channel": "/dev/ttyACM0",
                    "bitrate": 500000,
                },
            ],
            "trackers": [
                {"name": f"t{i}", "type": "single-axis", "link": link, "device_id": 3}
                for i, link in enumerate(("rs485", "lan", "can"))
            ],
        }
    )
    rtu, tcp, can = cfg.links
    assert isinstance(rtu, ModbusRtuLink) and (rtu.port, rtu.baudrate, rtu.parity) == (
        "/dev/ttyUSB0",
        19200,
        "E",
    )
    assert isinstance(tcp, ModbusTcpLink) and (tcp.host, tcp.tcp_port) == ("10.0.0.7", 1502)
    assert isinstance(can, CanopenLink) and (can.interface, can.channel, can.bitrate) == (
        "slcan",
        "/dev/ttyACM0",
        500000,
    )
    assert not any(link.is_hil for link in cfg.links)


def test_canopen_drives_occupy_one_node_per_axis():
    doc = {
        "site": {"latitude": 10, "longitude": 20},
        "control": {"period_s": 10},
        "links": [{"name": "can", "kind": "canopen"}],
        "trackers": [
            {"name": "d", "type": "dual-axis", "link": "can", "device_id": 4},
            {"name": "r", "type": "single-axis", "link": "can", "device_id": 5},
        ],
    }
    with pytest.raises(ConfigError, match=r"trackers\[1\].device_id: expected an id not used"):
        parse_config(doc)
    doc["trackers"][1]["device_id"] = 6
    assert len(parse_config(doc).trackers) == 2
    doc["trackers"][0]["device_id"] = 126
    with pytest.raises(ConfigError, match="within 1..126"):
        parse_config(doc)


def test_diffuse_needs_a_pyranometer_and_minute_sampling(tmp_path):
    with pytest.raises(ConfigError, match="diffuse.enabled.*pyranometer"):
        load_config(write(tmp_path, BASE + "[diffuse]\nenabled = true\n"))
    text = DEFAULT_CONFIG.read_text().replace("period_s = 60.0", "period_s = 120.0")
    with pytest.raises(ConfigError, match="every minute"):
        load_scenario(write(tmp_path, text))


def test_pyranometer_must_be_on_a_modbus_link(tmp_path):
    text = (
        BASE.replace('kind = "modbus-rtu"', 'kind = "canopen"')
        + '[pyranometer]\nlink = "a"\ndevice_id = 10\n'
    )
    with pytest.raises(ConfigError, match="pyranometer.link: expected a Modbus link"):
        load_config(write(tmp_path, text))


def test_syntax_error_non_utf8_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="valid TOML"):
        load_config(write(tmp_path, "[site\nlatitude = 1"))
    with pytest.raises(ConfigError, match="readable"):
        load_config(tmp_path / "nope.toml")
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(BASE.replace('name = "t"', 'name = "t\xe9"').encode("latin-1"))
    with pytest.raises(ConfigError, match="UTF-8"):
        load_config(bad)


def test_duplicate_device_on_a_link_is_refused(tmp_path):
    text = BASE + '[[trackers]]\nname = "u"\ntype = "single-axis"\nlink = "a"\ndevice_id = 1\n'
    with pytest.raises(ConfigError, match=r"trackers\[1\].device_id"):
        load_config(write(tmp_path, text))


def test_derived_defaults():
    cfg = parse_config(
        {
            "site": {"latitude": 1, "longitude": 2},
            "control": {"period_s": 1.0},
            "links": [{"name": "a", "kind": "modbus-tcp"}],
            "trackers": [{"name": "t", "type": "dual-axis", "link": "a", "device_id": 1}],
        }
    )
    assert isinstance(cfg, Config)
    assert cfg.control.lead_s == 0.5 and cfg.control.heartbeat_timeout_s == 5.0
    assert cfg.diffuse.enabled is False
