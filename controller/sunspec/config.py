"""The ``[sunspec]`` configuration table.

::

    [sunspec]
    enabled = true
    host = "127.0.0.1"          # bind address; "0.0.0.0" only on a plant network
    port = 1502                 # 0 = any free port (reported by the server)
    device_address = 1          # Modbus unit id, model 1 DA
    writes_enabled = false      # operator overrides from SCADA
    allow = ["127.0.0.1"]       # client addresses or networks allowed to write
    serial_number = ""          # model 1 SN

Errors name the file and key (:class:`controller.errors.ConfigError`) like the rest of
the configuration.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from pathlib import Path

from ..config import TableReader
from ..errors import ConfigError

_KEYS = {"enabled", "host", "port", "device_address", "writes_enabled", "allow", "serial_number"}


@dataclass(frozen=True)
class SunSpecConfig:
    """Northbound SunSpec server settings (see the module docstring for the TOML)."""

    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = 1502
    writes_enabled: bool = False
    allow: tuple[str, ...] = ("127.0.0.1",)
    device_address: int = 1
    serial_number: str = ""


def parse_sunspec(config_raw: dict, file: str | Path | None = None) -> SunSpecConfig:
    """Read the ``[sunspec]`` table of a parsed TOML document.

    Parameters
    ----------
    config_raw : dict
        The whole configuration document (``Config.raw`` or ``tomllib.load`` output).
    file : str or Path, optional
        Named in error messages.

    Returns
    -------
    SunSpecConfig
        Defaults (disabled) when the table is absent.

    Raises
    ------
    ConfigError
        A key has the wrong type or value, or is unknown.
    """
    root = TableReader(config_raw, file)
    if not root.has("sunspec"):
        return SunSpecConfig()
    t = root.table("sunspec")
    t.unknown_keys(_KEYS)
    d = SunSpecConfig()
    host = t.get("host", str, d.host, expected="an IP address to bind")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        # a literal address only: a host name could resolve to an unexpected interface
        raise ConfigError(file, f"{t.path}.host", "an IP address literal such as \"127.0.0.1\"", host) from None
    allow = t.get("allow", list, list(d.allow), expected="an array of IP addresses or networks")
    for i, a in enumerate(allow):
        try:
            if not isinstance(a, str):
                raise ValueError
            ipaddress.ip_network(a, strict=False)
        except ValueError:
            raise ConfigError(file, f"{t.path}.allow[{i}]",
                              "an IP address or network such as \"10.0.0.5\" or \"10.0.0.0/24\"", a) from None
    return SunSpecConfig(
        enabled=t.get("enabled", bool, d.enabled),
        host=host,
        port=t.integer("port", d.port, lo=0, hi=65535),
        writes_enabled=t.get("writes_enabled", bool, d.writes_enabled),
        allow=tuple(allow),
        device_address=t.integer("device_address", d.device_address, lo=1, hi=247),
        serial_number=t.get("serial_number", str, d.serial_number),
    )
