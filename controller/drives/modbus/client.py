"""pymodbus clients for configured links, and what a Modbus answer means for a retry.

Every device on one RS-485 line (drives, the pyranometer, later an anemometer) shares one
client per serial port: pymodbus opens a port exclusively, and a multidrop line has one
master anyway (the client serialises its requests).  :func:`modbus_client` is the one way
to get a client for a link, for drives and sensors alike.  Two links that name one port
must agree on its line settings, or the second is refused.
"""

from __future__ import annotations

import asyncio
import errno
import gc
import os
import termios
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusException
from serial import SerialException, serial_for_url

from ..base import DriveCommError, LinkSettingsError
from ..links import LinkConfig, ModbusRtuLink, ModbusTcpLink, serial_port_key
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
    (illegal function, address or value; device failure); ``code`` is its exception code."""

    def __init__(self, text: str, code: int | None = None):
        super().__init__(text)
        self.code = code


class ModbusBusy(Exception):
    """The device (or a gateway) answered "busy" or "no response from the target"."""


class ReplyMismatch(Exception):
    """A reply that does not answer the request sent: another function code, another
    number of registers, another address echoed.  On a serial line that is a reply late
    for an earlier request, or line noise that passed the CRC; never data to use."""


def retry_policy(retries: int) -> RetryPolicy:
    """The retry policy of every Modbus device: no answer, a garbled answer, a reply to
    another request or "busy" is retried; an exception response saying the request is
    wrong is final."""
    return RetryPolicy(
        retries, retry_on=(ModbusException, OSError, ModbusBusy, ReplyMismatch), final=(ModbusRefused,)
    )


#: Function code of the reply to each pymodbus client request we send.
_FUNCTION_CODES = {
    "read_holding_registers": 3,
    "read_input_registers": 4,
    "write_register": 6,
    "write_registers": 16,
    "readwrite_registers": 23,
}


def _arg(args: tuple[Any, ...], kwargs: dict[str, Any], i: int, name: str, default: Any = None) -> Any:
    return args[i] if len(args) > i else kwargs.get(name, default)


def verify_reply(name: str, rr: Any, args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
    """Raise :class:`ReplyMismatch` unless ``rr`` answers the request ``name(*args, **kwargs)``
    (a pymodbus client method): the function code, the number of registers read, the
    address (and count) echoed by a write.  A field the reply does not carry is not judged."""
    fc = _FUNCTION_CODES.get(name)
    if fc is None:
        return
    got = getattr(rr, "function_code", None)
    if got is not None and got != fc:
        raise ReplyMismatch(f"reply with function code {got} to a request with {fc}")
    words = list(getattr(rr, "registers", None) or [])
    if name in ("read_holding_registers", "read_input_registers", "readwrite_registers"):
        n = kwargs.get("read_count" if fc == 23 else "count", 1)
        if len(words) != n:
            raise ReplyMismatch(f"{len(words)} register(s) in the answer, {n} asked")
        return
    address = _arg(args, kwargs, 0, "address")
    echoed = getattr(rr, "address", None)
    if echoed is not None and echoed != address:
        raise ReplyMismatch(f"a write at {address} echoed at {echoed}")
    if name == "write_registers":
        n, count = len(_arg(args, kwargs, 1, "values", [])), getattr(rr, "count", None)
        if count is not None and count != n:
            raise ReplyMismatch(f"a write of {n} registers echoed as {count}")
    # write_register: the address only: a register that executes and clears itself
    # (COMMAND) is echoed by some devices with what it holds after the write


async def checked(request: Callable[..., Awaitable[Any]], *args: Any, **kwargs: Any) -> Any:
    """Await one pymodbus request; an exception response raises :class:`ModbusRefused` or
    :class:`ModbusBusy`, and a reply to another request :class:`ReplyMismatch` (for
    :func:`retry_policy`), instead of being returned."""
    rr = await request(*args, **kwargs)
    if rr.isError():
        code = getattr(rr, "exception_code", None)
        try:
            text = f"exception {int(code)} ({ExcCodes(code).name})" if code is not None else str(rr)
        except ValueError:
            text = f"exception {code}"
        if code is None or code in _TRANSIENT_CODES:
            raise ModbusBusy(text)
        raise ModbusRefused(text, int(code))
    verify_reply(getattr(request, "__name__", ""), rr, args, kwargs)
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

    @property
    def keys(self) -> str:
        """The settings as the plant file names them, for a port that refuses them."""
        return f"baudrate {self.baudrate}, parity {self.parity}, stopbits {self.stopbits}"


#: Why a serial port does not open, by errno, in the words of the one who must fix it.
_OPEN_ERRORS = {
    errno.ENOENT: "no such device (unplugged, or another name: see /dev/serial/by-id/)",
    errno.ENODEV: "no such device (unplugged?)",
    errno.ENXIO: "no such device (unplugged?)",
    errno.EACCES: "permission denied (is the user in the dialout group?)",
    errno.EPERM: "permission denied (is the user in the dialout group?)",
    # pyserial's exclusive flock (pymodbus opens exclusively), or TIOCEXCL (EBUSY)
    errno.EWOULDBLOCK: "in use by another program (is heliotrack run active?)",
    errno.EBUSY: "in use by another program (is heliotrack run active?)",
}


def port_error(port: str, exc: BaseException, settings: LineSettings | None = None) -> str:
    """One line saying why pyserial could not open or configure ``port``: a missing device,
    a permission, a port another program holds, a file that is no serial port, line
    settings the port refuses (``termios.error``, not an OSError), a bad URL."""
    if isinstance(exc, termios.error):  # tcsetattr: the port exists but refuses a setting
        args = exc.args
        why = str(args[1]) if len(args) > 1 else str(exc)
        if args and args[0] == errno.ENOTTY:
            return f"{port}: not a serial port (not a tty)"
        where = f" ({settings.keys})" if settings is not None else ""
        return f"{port}: cannot configure the port{where}: {why}"
    code = getattr(exc, "errno", None)
    if code in _OPEN_ERRORS:
        return f"{port}: {_OPEN_ERRORS[code]}"
    text = str(exc)
    if "Inappropriate ioctl" in text:  # pyserial's "Could not configure port: (25, ...)"
        return f"{port}: not a serial port (not a tty)"
    if isinstance(exc, OSError) and code is not None:
        return f"{port}: cannot open the port: {os.strerror(code)}"
    return f"{port}: cannot open the port: {text or type(exc).__name__}"


def _why_not_open(port: str, settings: LineSettings) -> str:
    """Open ``port`` as pymodbus does, for the reason it failed: pymodbus catches pyserial's
    exception (an OSError) and only returns False.  Called after a failed open only; not
    for a URL (``rfc2217://``), whose open may wait seconds on an unreachable server."""
    if "://" in port:
        return f"{port}: cannot open the port (is the serial device server reachable?)"
    try:
        serial = serial_for_url(
            port,
            exclusive=True,
            baudrate=settings.baudrate,
            parity=settings.parity,
            stopbits=settings.stopbits,
            bytesize=8,
            timeout=0,
        )
    except (SerialException, OSError, termios.error, ValueError) as exc:
        return port_error(port, exc, settings)
    serial.close()
    return f"{port}: cannot open the port (it opened when tried again: a passing fault?)"


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
        self.key = serial_port_key(port)
        self.settings = settings
        self.link_name = link_name
        self.users = 0
        self._connecting: asyncio.Lock | None = None
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
        key = serial_port_key(link.port)
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
        """Open the port (once, however many devices of the line ask at the same time: a
        second concurrent open of one pymodbus client fails); True when it is open.

        Raises
        ------
        DriveCommError
            The port does not open or refuses the line settings; the message names the
            port and why (``/dev/ttyUSB0: permission denied (...)``).
        """
        if self.client.connected:
            return True
        if self._connecting is None:
            self._connecting = asyncio.Lock()
        async with self._connecting:
            if self.client.connected:
                return True
            refused = ""
            try:
                if await self.client.connect():
                    return True
            except (termios.error, SerialException, ValueError) as exc:
                # what pymodbus does not catch: a setting the port refuses (termios.error is
                # no OSError), a URL pyserial does not know (ValueError)
                refused = port_error(self.port, exc, self.settings)
            if refused:
                # the transport pymodbus was making when the setting was refused holds the
                # port open (and flocked) from a reference cycle: free it now, or the next
                # open finds the port "in use"
                gc.collect()
                self.client.close()
                raise DriveCommError(refused)
            raise DriveCommError(await asyncio.to_thread(_why_not_open, self.port, self.settings))

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


async def why_tcp_not_open(client: Any, elapsed_s: float) -> str:
    """Why a Modbus TCP client's ``connect()`` returned False (pymodbus logs the reason and
    keeps none): a quick refusal is asked again for its words; a connection attempt that
    took the whole timeout is a host that does not answer.  '' for a serial client."""
    params = getattr(client, "comm_params", None)
    host, port = getattr(params, "host", None), getattr(params, "port", None)
    if not isinstance(host, str) or not isinstance(port, int) or host.startswith(("/", "ptyfd:", "rfc2217:")):
        return ""
    timeout = float(getattr(params, "timeout_connect", 0) or 0)
    if timeout and elapsed_s >= 0.8 * timeout:
        return f": {host}:{port} does not answer within {timeout:g} s (host down, or a firewall?)"
    try:
        _, writer = await asyncio.wait_for(asyncio.open_connection(host, port), min(timeout or 1.0, 1.0))
    except TimeoutError:
        return f": {host}:{port} does not answer (host down, or a firewall?)"
    except OSError as exc:
        why = (os.strerror(exc.errno) if exc.errno else str(exc)).lower()  # asyncio's strerror names no cause
        hint = " (nothing listens there: the gateway's address or port?)" if "refused" in why else ""
        return f": {host}:{port}: {why}{hint}"
    writer.close()
    return f": {host}:{port} accepted a connection, then pymodbus could not use it"
