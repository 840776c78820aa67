"""pymodbus clients for configured links, and what a Modbus answer means for a retry.

Every device on one RS-485 line (drives, the pyranometer, later an anemometer) shares one
client per serial port: pymodbus opens a port exclusively, and a multidrop line has one
master anyway (the client serialises its requests).  :func:`modbus_client` is the one way
to get a client for a link, for drives and sensors alike.  Two links that name one port
must agree on its line settings, or the second is refused.
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusException

from ..base import LinkSettingsError
from ..links import LinkConfig, ModbusRtuLink, ModbusTcpLink
from ..retry import RetryPolicy

#: Exception responses that mean "not now" rather than "never": worth another attempt.
_TRANSIENT_CODES = frozenset(
    {
        ExcCodes.ACKNOWLEDGE,
        ExcCodes.DEVICE_BUSY,
        ExcCodes.GATEWAY_PATH_UNAVIABLE,
        ExcCodes.GATEWAY_NO_RESPONSE,
    }
)


class ModbusRefused(Exception):
    """The device answered with an exception response another attempt would repeat
    (illegal function, address or value; device failure)."""


class ModbusBusy(Exception):
    """The device (or a gateway) answered "busy" or "no response from the target"."""


def retry_policy(retries: int) -> RetryPolicy:
    """The retry policy of every Modbus device: no answer, a garbled answer or "busy" is
    retried; an exception response saying the request is wrong is final."""
    return RetryPolicy(retries, retry_on=(ModbusException, OSError, ModbusBusy), final=(ModbusRefused,))


async def checked(request: Callable[..., Awaitable[Any]], *args: Any, **kwargs: Any) -> Any:
    """Await one pymodbus request; an exception response raises :class:`ModbusRefused` or
    :class:`ModbusBusy` (for :func:`retry_policy`) instead of being returned."""
    rr = await request(*args, **kwargs)
    if rr.isError():
        code = getattr(rr, "exception_code", None)
        try:
            text = f"exception {int(code)} ({ExcCodes(code).name})" if code is not None else str(rr)
        except ValueError:
            text = f"exception {code}"
        raise (ModbusBusy if code is None or code in _TRANSIENT_CODES else ModbusRefused)(text)
    return rr


@dataclass(frozen=True)
class LineSettings:
    """What the client of one serial port is opened with (8 data bits, as RTU requires)."""

    baudrate: int
    parity: str
    stopbits: int
    timeout_s: float

    @classmethod
    def of(cls, link: ModbusRtuLink) -> LineSettings:
        return cls(link.baudrate, link.parity, link.stopbits, link.timeout_s)

    def __str__(self) -> str:
        return f"{self.baudrate} bit/s 8{self.parity}{self.stopbits}, timeout {self.timeout_s:g} s"


def _port_key(port: str) -> str:
    """One key per physical port: ``/dev/serial/by-id/...`` and ``/dev/ttyUSB0`` agree."""
    return port if "://" in port else os.path.realpath(port)


class SharedSerialClient:
    """The pymodbus client of one serial port, shared by every device of every link on it.

    Acquired per device with :meth:`acquire`; the port closes when its last user closes.
    Request methods (``read_holding_registers`` ...) are the client's own.
    """

    _open: ClassVar[dict[str, SharedSerialClient]] = {}

    def __init__(self, port: str, settings: LineSettings, link_name: str):
        self.client = AsyncModbusSerialClient(
            port,
            baudrate=settings.baudrate,
            parity=settings.parity,
            stopbits=settings.stopbits,
            bytesize=8,
            timeout=settings.timeout_s,
            retries=0,
            reconnect_delay=0,
        )
        self.port = port
        self.key = _port_key(port)
        self.settings = settings
        self.link_name = link_name
        self.users = 0
        try:  # a client belongs to the event loop it first runs on
            self.loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self.loop = None

    @classmethod
    def acquire(cls, link: ModbusRtuLink) -> SharedSerialClient:
        """The client of ``link.port``, opened with the link's settings if it is new.

        Raises
        ------
        LinkSettingsError
            Another link already uses the port with other line settings.
        """
        key = _port_key(link.port)
        settings = LineSettings.of(link)
        shared = cls._open.get(key)
        if shared is not None and shared.loop is not None and shared.loop.is_closed():
            shared = None  # left over from a finished event loop: unusable anyway
        if shared is None:
            shared = cls._open[key] = cls(link.port, settings, link.name)
        elif shared.settings != settings:
            raise LinkSettingsError(
                f"links {shared.link_name!r} and {link.name!r} both open serial port "
                f"{link.port} with different settings ({shared.settings} vs {settings}); "
                "a line has one setting: make them equal, or make them one link"
            )
        shared.users += 1
        return shared

    def __getattr__(self, name: str) -> Any:
        return getattr(self.client, name)

    @property
    def connected(self) -> bool:
        return bool(self.client.connected)

    async def connect(self) -> bool:
        return self.client.connected or await self.client.connect()

    def close(self) -> None:
        self.users -= 1
        if self.users <= 0:
            self.client.close()
            if self._open.get(self.key) is self:
                del self._open[self.key]


def _simulator_only(link: LinkConfig, key: str) -> LinkSettingsError:
    return LinkSettingsError(
        f'link {link.name!r}: {key} = "hil" names a device that only '
        "`heliotrack simulate` provides; give the real one"
    )


def modbus_client(link: LinkConfig) -> Any:
    """A pymodbus asyncio client (not yet connected) for one device on ``link``.

    On ``modbus-rtu`` the client of the port, shared with every other device on it; on
    ``modbus-tcp`` a connection of the device's own.  Close it once per call.

    Raises
    ------
    LinkSettingsError
        ``link`` is not a Modbus link, names the simulator's device outside a simulation,
        or conflicts with another link on the same port.
    """
    if isinstance(link, ModbusRtuLink):
        if link.is_hil:
            raise _simulator_only(link, "port")
        return SharedSerialClient.acquire(link)
    if isinstance(link, ModbusTcpLink):
        if link.is_hil:
            raise _simulator_only(link, "host")
        return AsyncModbusTcpClient(
            link.host, port=link.tcp_port, timeout=link.timeout_s, retries=0, reconnect_delay=0
        )
    raise LinkSettingsError(
        f"link {link.name!r} is {link.kind!r}, not a Modbus link (modbus-rtu or modbus-tcp)"
    )


def endpoint(link: LinkConfig) -> str:
    """Where a device on ``link`` is, for messages (``/dev/ttyUSB0``, ``10.0.0.5:502``)."""
    if isinstance(link, ModbusRtuLink):
        return link.port
    if isinstance(link, ModbusTcpLink):
        return f"{link.host}:{link.tcp_port}"
    return link.name
