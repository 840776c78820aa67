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
        (
            lambda s: s.replace("longitude = 20", 'longitude = 20\ntimezone = "Europe/Osl"'),
            "site.timezone",
            "an IANA time zone name",
        ),
        (
            lambda s: s.replace("longitude = 20", 'longitude = 20\ntimezone = "../../etc/passwd"'),
            "site.timezone",
            "IANA",
        ),
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
            # CANopen's consumer heartbeat holds at most 65.535 s (the default is 180 s)
            "control": {"heartbeat_timeout_s": 65.0},
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
        + '[pyranometer]\nlink = "a"\ndevice_id = 10\n[control]\nheartbeat_timeout_s = 65.0\n'
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


def _plant(links, trackers, **extra):
    return {
        "site": {"latitude": 10, "longitude": 20},
        "control": {"period_s": 10},
        "links": links,
        "trackers": trackers,
        **extra,
    }


@pytest.mark.parametrize(
    ("links", "second_id", "match"),
    [
        # two links on one RS-485 port: two masters on one line
        (
            [
                {"name": "l1", "kind": "modbus-rtu", "port": "/dev/ttyUSB0"},
                {"name": "l2", "kind": "modbus-rtu", "port": "/dev/ttyUSB0"},
            ],
            2,
            r"links\[1\].port: expected a port no other link opens",
        ),
        # one gateway reached by two links: one unit-id space
        (
            [
                {"name": "l1", "kind": "modbus-tcp", "host": "10.0.0.5"},
                {"name": "l2", "kind": "modbus-tcp", "host": "10.0.0.5"},
            ],
            1,
            r"trackers\[1\].device_id: expected an id not used on the bus of link 'l2' already \(by d1\)",
        ),
        # one CAN bus: a dual-axis drive at 5 holds nodes 5 and 6
        (
            [
                {"name": "l1", "kind": "canopen", "interface": "socketcan", "channel": "can0"},
                {"name": "l2", "kind": "canopen", "interface": "socketcan", "channel": "can0"},
            ],
            6,
            r"trackers\[1\].device_id: expected an id not used",
        ),
    ],
)
def test_device_ids_are_unique_per_physical_bus_not_per_link(links, second_id, match):
    trackers = [
        {
            "name": "d1",
            "type": "dual-axis",
            "link": "l1",
            "device_id": 1 if links[0]["kind"] != "canopen" else 5,
        },
        {"name": "d2", "type": "single-axis", "link": "l2", "device_id": second_id},
    ]
    with pytest.raises(ConfigError, match=match):
        parse_config(_plant(links, trackers))
    if links[0]["kind"] != "modbus-rtu":  # other addresses on the shared bus are fine
        trackers[1]["device_id"] = 7
        assert len(parse_config(_plant(links, trackers)).trackers) == 2


def test_the_simulators_links_are_buses_of_their_own():
    links = [{"name": "l1", "kind": "modbus-rtu"}, {"name": "l2", "kind": "modbus-rtu"}]
    trackers = [
        {"name": "d1", "type": "dual-axis", "link": "l1", "device_id": 1},
        {"name": "d2", "type": "single-axis", "link": "l2", "device_id": 1},
    ]
    assert len(parse_config(_plant(links, trackers)).trackers) == 2


def test_a_long_period_needs_a_watchdog_timeout_the_drives_can_hold():
    doc = _plant(
        [{"name": "a", "kind": "modbus-tcp"}],
        [{"name": "t", "type": "dual-axis", "link": "a", "device_id": 1}],
    )
    doc["control"] = {"period_s": 3000.0}
    with pytest.raises(
        ConfigError,
        match=r"control.heartbeat_timeout_s: expected a value set \(the default, 3 x period_s = 9000 s",
    ):
        parse_config(doc)
    doc["control"]["heartbeat_timeout_s"] = 6000.0
    assert parse_config(doc).control.heartbeat_timeout_s == 6000.0


def test_a_lead_beyond_the_period_is_refused():
    doc = _plant(
        [{"name": "a", "kind": "modbus-tcp"}],
        [{"name": "t", "type": "dual-axis", "link": "a", "device_id": 1}],
    )
    doc["control"] = {"period_s": 60.0, "lead_s": 3600.0}
    with pytest.raises(ConfigError, match=r"control.lead_s: expected at most control.period_s \(60 s"):
        parse_config(doc)
    doc["control"]["lead_s"] = 60.0
    assert parse_config(doc).control.lead_s == 60.0


@pytest.mark.parametrize(
    ("table", "target", "match"),
    [
        (
            "[store]\npath",
            "plant.toml",
            r"store.path: expected a file of its own \(this is the configuration file itself\)",
        ),
        ("[store]\npath", "calibration", r"store.path: expected a file's path \(this is a folder\)"),
        ("[sunpath]\nstate", "calibration", r"sunpath.state: expected a file's path \(this is a folder\)"),
        (
            "[sunpath]\nstate",
            "calibration/b.toml",
            r"sunpath.state: expected a file of its own \(this is hotspot.calibration\)",
        ),
        ("[sunpath]\nstate", "same.db", r"sunpath.state: expected a file other than store.path"),
    ],
)
def test_a_state_file_may_not_be_a_folder_or_a_file_the_controller_reads(tmp_path, table, target, match):
    """An unreadable state file is moved aside at start: a plant file or a bundle named
    there had been renamed, and a folder replaced by the store (an audit's finding)."""
    (tmp_path / "calibration").mkdir()
    bundle = tmp_path / "calibration" / "b.toml"
    bundle.write_text("")
    text = BASE + f'[hotspot]\ncalibration = "calibration/b.toml"\n{table} = "{target}"\n'
    if "same.db" in target:
        text += '[store]\npath = "same.db"\n'
    plant = tmp_path / "plant.toml"
    plant.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_config(plant)
    assert bundle.exists() and plant.read_text() == text and (tmp_path / "calibration").is_dir()


def test_a_snow_or_hail_stow_outside_a_trackers_travel_is_refused():
    """An audit's case: -10 deg with limits [0, 90] had been clamped to 0 without a word."""
    doc = _plant(
        [{"name": "a", "kind": "modbus-tcp"}],
        [{"name": "t", "type": "dual-axis", "link": "a", "device_id": 1}],
    )
    doc["stow"] = {"snow_dual_axis_elevation_deg": -10.0}
    with pytest.raises(
        ConfigError,
        match=r"stow.snow_dual_axis_elevation_deg: expected an elevation within every tracker's limits \(t: \[0, 90\]\)",
    ):
        parse_config(doc)


def test_a_mean_wind_stow_at_or_above_the_gust_stow_is_refused():
    doc = _plant(
        [{"name": "a", "kind": "modbus-tcp"}],
        [{"name": "t", "type": "dual-axis", "link": "a", "device_id": 1}],
        wind={"link": "a", "device_id": 9, "gust_stow_m_s": 20.0, "mean_stow_m_s": 25.0},
    )
    with pytest.raises(ConfigError, match=r"wind.mean_stow_m_s: expected less than gust_stow_m_s \(20 m/s"):
        parse_config(doc)


def test_a_byte_order_mark_is_not_a_toml_error(tmp_path):
    p = tmp_path / "plant.toml"
    p.write_bytes(b"\xef\xbb\xbf" + (BASE + ROW).encode())
    assert len(load_config(p).trackers) == 2


def test_sunspec_may_not_serve_the_endpoint_a_link_dials():
    doc = _plant(
        [{"name": "gw", "kind": "modbus-tcp", "host": "127.0.0.1", "tcp_port": 502}],
        [{"name": "t", "type": "dual-axis", "link": "gw", "device_id": 1}],
        sunspec={"enabled": True, "host": "127.0.0.1", "port": 502},
    )
    with pytest.raises(ConfigError, match=r"sunspec.port: expected a port other than links\[0\]'s"):
        parse_config(doc)
    doc["sunspec"]["port"] = 1502
    assert parse_config(doc).sunspec.port == 1502


def test_a_link_whose_retries_outlast_the_cycle_is_warned_about(tmp_path, capsys):
    """An audit's case: a drive answering every other request, at a 1 s period with
    timeout_s 0.5 and one retry, was taken for lost ('no answer within 0.8 s')."""
    from controller.drives.links import link_timing_warnings
    from tests.controller.validate import validated

    links = [{"name": "lan", "kind": "modbus-tcp", "host": "10.0.0.5", "timeout_s": 0.5, "retries": 1}]
    trackers = [{"name": "t", "type": "dual-axis", "link": "lan", "device_id": 1}]
    doc = _plant(links, trackers)
    doc["control"] = {"period_s": 1.0}
    (warning,) = link_timing_warnings(parse_config(doc))
    assert (
        warning.startswith("links[0] (lan): one transaction with its retries may take 1 s")
        and "over the 0.8 s a drive has each period" in warning
    )
    doc["control"] = {"period_s": 60.0}
    assert link_timing_warnings(parse_config(doc)) == []
    _, err = validated(
        tmp_path,
        capsys,
        "[site]\nlatitude = 32.5\nlongitude = 48.3\n[control]\nperiod_s = 1.0\n"
        '[[links]]\nname = "lan"\nkind = "modbus-tcp"\nhost = "10.0.0.5"\ntimeout_s = 0.5\nretries = 1\n'
        '[[trackers]]\nname = "t"\ntype = "dual-axis"\nlink = "lan"\ndevice_id = 1\n',
    )
    assert "one transaction with its retries may take 1 s" in err


def test_two_links_on_one_port_through_a_symlink_are_refused(tmp_path):
    """An audit's case: one drive as two trackers, link a on /dev/pts/N and link b on a
    symlink to it (as /dev/serial/by-id/... is to /dev/ttyUSB0), passed validate, check and run."""
    from hil.pty import PtyLink

    with PtyLink.open() as pty:
        alias = tmp_path / "by-id-port0"
        alias.symlink_to(pty.path)
        links = [
            {"name": "a", "kind": "modbus-rtu", "port": pty.path},
            {"name": "b", "kind": "modbus-rtu", "port": str(alias)},
        ]
        trackers = [
            {"name": "t1", "type": "dual-axis", "link": "a", "device_id": 1},
            {"name": "t2", "type": "dual-axis", "link": "b", "device_id": 1},
        ]
        with pytest.raises(ConfigError) as e:
            parse_config(_plant(links, trackers))
        assert e.value.key == "links[1].port" and e.value.got == str(alias)
        assert f"link 'a' has it as {pty.path}; both are {pty.path}" in str(e.value)


def test_an_index_in_an_error_says_which_tracker_or_link_it_means():
    """`trackers[1]` counts from 0, which a reader of the file does not: an installer's walk
    read `trackers[1].gcrr` as the first tracker.  The item's own name is said with it."""
    doc = {
        "site": {"latitude": 10, "longitude": 20},
        "links": [{"name": "rs485-1", "kind": "modbus-rtu", "port": "/dev/ttyUSB0"}],
        "trackers": [
            {"name": "dual-1", "type": "dual-axis", "link": "rs485-1", "device_id": 1},
            {"name": "row-1", "type": "single-axis", "link": "rs485-1", "device_id": 2, "gcrr": 0.4},
        ],
    }
    with pytest.raises(ConfigError, match=r"trackers\[1\]\.gcrr: .* \(trackers\[1\] is 'row-1'\)$"):
        parse_config(doc)
    del doc["trackers"][1]["gcrr"]
    doc["trackers"][1]["link"] = "rs485-2"
    with pytest.raises(ConfigError, match=r"trackers\[1\]\.link: .* \(trackers\[1\] is 'row-1'\)$"):
        parse_config(doc)
    doc["trackers"][1]["link"] = "rs485-1"
    doc["links"].append({"name": "rs485-1", "kind": "modbus-tcp", "host": "127.0.0.1"})
    with pytest.raises(ConfigError, match=r"links\[1\]\.name: .* \(links\[1\] is 'rs485-1'\)$"):
        parse_config(doc)
