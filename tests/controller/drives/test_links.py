"""Per-kind ``[[links]]`` settings, validated from TOML."""

import pytest

from controller.config import parse_config
from controller.drives.links import CanopenLink, ModbusRtuLink
from controller.errors import ConfigError


def plant(link: dict, period_s: float = 10.0, **control) -> dict:
    return {
        "site": {"latitude": 10, "longitude": 20},
        "control": {"period_s": period_s, **control},
        "links": [link],
        "trackers": [{"name": "row", "type": "single-axis", "link": link["name"], "device_id": 3}],
    }


def test_rtu_line_settings_from_toml():
    cfg = parse_config(
        plant(
            {
                "name": "rs485",
                "kind": "modbus-rtu",
                "port": "/dev/ttyUSB0",
                "baudrate": 9600,
                "parity": "E",
                "stopbits": 2,
            }
        )
    )
    link = cfg.links[0]
    assert isinstance(link, ModbusRtuLink)
    assert (link.baudrate, link.parity, link.stopbits) == (9600, "E", 2)
    with pytest.raises(ConfigError, match=r"links\[0\].parity: expected one of .*got 'X'"):
        parse_config(plant({"name": "rs485", "kind": "modbus-rtu", "parity": "X"}))
    with pytest.raises(ConfigError, match=r"links\[0\].stopbits"):
        parse_config(plant({"name": "rs485", "kind": "modbus-rtu", "stopbits": 3}))


def test_canopen_interface_is_one_python_can_knows():
    cfg = parse_config(
        plant(
            {
                "name": "can",
                "kind": "canopen",
                "interface": "slcan",
                "channel": "/dev/ttyACM0",
                "bitrate": 500000,
                "pdo_mapping": "eds",
            }
        )
    )
    link = cfg.links[0]
    assert isinstance(link, CanopenLink) and link.pdo_mapping == "eds"
    with pytest.raises(
        ConfigError,
        match=r"links\[0\].interface: expected a python-can "
        r"interface \(.*socketcan.*\), got 'sockcan'",
    ):
        parse_config(plant({"name": "can", "kind": "canopen", "interface": "sockcan"}))


def test_canopen_drives_need_a_watchdog_their_heartbeat_object_can_hold():
    can = {"name": "can", "kind": "canopen"}
    # The default watchdog, 3 x 60 s, does not fit 0x1016's 16-bit milliseconds.
    with pytest.raises(
        ConfigError,
        match=r"control.heartbeat_timeout_s: expected at most "
        r"65.535 s with drives on CANopen link 'can'",
    ):
        parse_config(plant(can, period_s=60.0))
    cfg = parse_config(plant(can, period_s=60.0, heartbeat_timeout_s=65.0))
    assert cfg.control.heartbeat_timeout_s == 65.0
    # Modbus drives take the long default.
    rtu = parse_config(plant({"name": "rs485", "kind": "modbus-rtu"}, period_s=60.0))
    assert rtu.control.heartbeat_timeout_s == 180.0
