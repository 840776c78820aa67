"""What a ``[[links]]`` table holds, per link kind (the schema of each backend's settings).

Each drive backend names its settings class in ``config_type``; the configuration reads a
``[[links]]`` table with the class of its ``kind`` (see :mod:`controller.drives.registry`),
so a backend brings its own keys and a typo in any of them is an error.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Literal

from ..schema import Where, setting


@dataclass(frozen=True, kw_only=True)
class LinkConfig:
    """One physical link (an RS-485 line, a TCP network, a CAN bus) that drives share."""

    name: str = setting(doc="Name that trackers and sensors refer to.", nonempty=True)
    kind: str = setting(doc="The backend: a registered link kind.")
    timeout_s: float = setting(0.5, doc="Answer timeout of one transaction.", unit="s", ge=0.001, le=60)
    retries: int = setting(2, doc="Extra attempts after a failed transaction.", ge=0, le=10)

    @property
    def is_hil(self) -> bool:
        """Names a device only the simulator provides (``port = "hil"``)."""
        return False

    @property
    def bus(self) -> tuple[str, ...]:
        """The physical bus this link is on: two links with the same ``bus`` share one
        address space (device ids must differ across them).  A simulator's link is a bus of
        its own."""
        return ("link", self.name)


@dataclass(frozen=True, kw_only=True)
class ModbusRtuLink(LinkConfig):
    """Modbus RTU on a serial line (RS-485), many slaves on one port."""

    kind: Literal["modbus-rtu"] = setting("modbus-rtu", doc="Modbus RTU.")
    port: str = setting(
        "hil",
        doc="Serial device or pyserial URL (`/dev/ttyUSB0`, "
        '`rfc2217://host:port`); "hil": a pseudo-terminal the simulator makes.',
        nonempty=True,
    )
    baudrate: int = setting(115200, doc="Line speed.", unit="bit/s", ge=1200, le=4_000_000)
    parity: Literal["N", "E", "O"] = setting("N", doc="Parity: none, even or odd.")
    stopbits: Literal[1, 2] = setting(1, doc="Stop bits.")

    @property
    def is_hil(self) -> bool:
        return self.port == "hil"

    @property
    def bus(self) -> tuple[str, ...]:
        # the device, not its name: a symlink (/dev/serial/by-id/...) and its target are one line
        return super().bus if self.is_hil else ("serial", serial_port_key(self.port))


def serial_port_key(port: str) -> str:
    """One key per physical serial port: ``/dev/serial/by-id/...`` and the ``/dev/ttyUSB0``
    it links to agree; a pyserial URL (``rfc2217://...``) is its own key."""
    return port if "://" in port else os.path.realpath(port)


@dataclass(frozen=True, kw_only=True)
class ModbusTcpLink(LinkConfig):
    """Modbus TCP: each device its own endpoint (or a gateway with unit ids)."""

    kind: Literal["modbus-tcp"] = setting("modbus-tcp", doc="Modbus TCP.")
    host: str = setting(
        "hil",
        doc='Address of the device or gateway; "hil": an endpoint the simulator serves on 127.0.0.1.',
        nonempty=True,
    )
    tcp_port: int = setting(502, doc="TCP port (0: the simulator picks a free one).", ge=0, le=65535)

    @property
    def is_hil(self) -> bool:
        return self.host == "hil"

    @property
    def bus(self) -> tuple[str, ...]:
        # a gateway's unit ids are one address space, whichever link reaches it
        return super().bus if self.is_hil else ("tcp", self.host.lower(), str(self.tcp_port))


@dataclass(frozen=True, kw_only=True)
class CanopenLink(LinkConfig):
    """CANopen (CiA 402) through any python-can interface; a drive is one node per axis."""

    kind: Literal["canopen"] = setting("canopen", doc="CANopen CiA 402.")
    interface: str = setting(
        "virtual",
        doc="python-can interface: `socketcan`, `slcan`, `pcan`, `kvaser`, `virtual`, ...",
        nonempty=True,
    )
    channel: str = setting(
        "hil",
        doc="python-can channel (`can0`, `/dev/ttyACM0`, "
        '`PCAN_USBBUS1`); "hil": a bus the simulator provides.',
        nonempty=True,
    )
    bitrate: int = setting(
        250_000, doc="CAN bit rate (ignored by `virtual`).", unit="bit/s", ge=10_000, le=1_000_000
    )
    pdo_mapping: Literal["read", "eds"] = setting(
        "read",
        doc="Where the master learns each drive's PDO mapping: read by SDO at connect, "
        'or "eds": taken from the EDS (faster start-up of many drives that keep the default '
        "mapping).",
    )

    @property
    def is_hil(self) -> bool:
        return self.channel == "hil"

    @property
    def bus(self) -> tuple[str, ...]:
        if self.is_hil or self.interface == "virtual":  # python-can's virtual buses are per channel
            return super().bus if self.is_hil else ("can", "virtual", self.channel)
        return ("can", self.channel)

    def __schema_check__(self, at: Where) -> CanopenLink:
        from can.interfaces import VALID_INTERFACES  # python-can's own list, plug-ins too

        if self.interface not in VALID_INTERFACES:
            raise at.child("interface").error(
                f"a python-can interface ({', '.join(sorted(VALID_INTERFACES))})", self.interface
            )
        return self


def link_timing_warnings(config) -> list[str]:
    """One line per link of ``config`` (a :class:`controller.config.Config`) on which one
    transaction with all its attempts takes longer than a realtime cycle allows
    (``0.8 x period_s``): a drive that needs its retries is then taken for lost while it
    still answers."""
    budget = max(0.8 * config.control.period_s, 0.2)
    out = []
    for i, link in enumerate(config.links):
        ladder = link.timeout_s * (link.retries + 1)
        if ladder > budget:
            out.append(
                f"links[{i}] ({link.name}): one transaction with its retries may take {ladder:g} s "
                f"(timeout_s {link.timeout_s:g} x {link.retries + 1} attempts), over the "
                f"{budget:g} s a drive has each period: one that needs its retries is taken for "
                "lost; lower timeout_s or retries, or raise control.period_s"
            )
    return out
