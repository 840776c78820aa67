"""The northbound SunSpec Modbus TCP server (pymodbus), for plant SCADA.

Runs its own asyncio loop in a daemon thread (the controller's code stays synchronous;
the thread is :class:`firmware_protocol.server_thread.ServerThread`, shared with the
emulator's Modbus servers), serves one pymodbus ``SimDevice`` whose registers are re-rendered from the controller's
snapshot on every read, and turns accepted writes into :class:`OverrideCommand`.

Write policy, in the order it is checked:

1. writes disabled (default)          -> exception 1 (ILLEGAL FUNCTION)
2. client address not in the allowlist -> exception 1 (same answer: a probing client
                                          learns nothing about the allowlist)
3. not whole writable model 601 points -> exception 2 (ILLEGAL DATA ADDRESS)
4. bad value (angle out of range or limits, unknown Ctl) -> exception 3 (ILLEGAL DATA VALUE)
5. ``on_override`` raised              -> exception 4 (SERVER DEVICE FAILURE), staging undone

Only function codes 3 and 4 (read) and 6 and 16 (write) are served.

Client address: pymodbus 3.16 passes neither the peer to the datastore nor to the
``trace_*`` hooks, but each connection gets its own ``ServerRequestHandler`` (an asyncio
protocol whose ``transport`` knows the peer) and each request is handled in its own task.
A handler subclass puts the peer in a :class:`contextvars.ContextVar` for the duration of
``handle_request``, where the SimDevice action reads it.  No pymodbus code is copied.
"""

from __future__ import annotations

import contextvars
import copy
import errno
import ipaddress
import logging
import math
import socket
import time
from collections.abc import Callable, Iterable
from typing import Self

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ModbusIOException, NoSuchIdException
from pymodbus.pdu import ExceptionResponse
from pymodbus.server import ModbusTcpServer
from pymodbus.server.requesthandler import ServerRequestHandler
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simcore import SimCore
from pymodbus.transaction import TransactionManager

from firmware_protocol.server_thread import ServerThread, ServerThreadError

from .config import SunSpecConfig
from .control import ControlTable, WriteRefused
from .encode import Encoder, Identity
from .models import SUNSPEC_BASE_ADDRESS, SunSpecMap
from .snapshot import OverrideCommand, PlantSnapshot, StowRequest

log = logging.getLogger("heliotrack.sunspec")

_PEER: contextvars.ContextVar[str | None] = contextvars.ContextVar("sunspec_peer", default=None)
# set by the SimDevice action when it handles a write itself (and logs a refusal)
_WRITE_SEEN: contextvars.ContextVar[bool] = contextvars.ContextVar("sunspec_write_seen", default=False)
_READ_FCS = {3, 4}
_WRITE_FCS = {6, 16}
_SERVED_FCS = _READ_FCS | _WRITE_FCS

SnapshotFn = Callable[[], PlantSnapshot]
OverrideFn = Callable[[OverrideCommand | StowRequest], None]


class SunSpecServerError(RuntimeError):
    """The server could not start (address in use, bad snapshot...)."""


class _PeerAwareHandler(ServerRequestHandler):
    """Request handler that exposes the client's IP address to the datastore, and
    answers a request pymodbus cannot decode with the request's own function code."""

    def callback_data(self, data: bytes, addr: tuple | None = None) -> int:
        # ServerRequestHandler.callback_data answers an undecodable request (FC 3 with a
        # quantity outside 1..125, an unknown function) with function code 0x80 and
        # exception 1, which no client can match to its request.  Modbus: the request's
        # function code + 0x80, exception 3 for a bad quantity of a served function,
        # exception 1 for a function not served.
        try:
            used_len = TransactionManager.callback_data(self, data, addr)
        except ModbusIOException as exc:
            self.server_send(_undecodable_answer(data, exc, self.server.context), addr)
            return len(data)
        if self.last_pdu:
            self.loop.call_soon(self.handle_later)
        return used_len

    async def handle_request(self):
        peer = self.transport.get_extra_info("peername") if self.transport else None
        token = _PEER.set(peer[0] if peer else None)
        try:
            await super().handle_request()
        finally:
            _PEER.reset(token)


def _undecodable_answer(frame: bytes, exc: ModbusIOException, context) -> ExceptionResponse:
    """The exception response to a Modbus TCP ``frame`` (MBAP header first) that pymodbus
    could not decode."""
    fc = frame[7] & 0x7F if len(frame) > 7 else 0  # after the 7-byte MBAP header
    if exc.dev_id not in getattr(context, "devices", {exc.dev_id: None}):
        code = ExcCodes.GATEWAY_NO_RESPONSE  # not our unit id, as a decodable request
    elif fc in _SERVED_FCS:
        code = ExcCodes.ILLEGAL_VALUE
    else:
        code = ExcCodes.ILLEGAL_FUNCTION
    return ExceptionResponse(fc, exception_code=code, device_id=exc.dev_id, transaction=exc.transaction_id)


class _PeerAwareTcpServer(ModbusTcpServer):
    def callback_new_connection(self):
        return _PeerAwareHandler(self, self.trace_packet, self.trace_pdu, self.trace_connect)


class _SingleUnitCore(SimCore):
    """SimCore that answers only our unit id (others: exception 0x0B via NoSuchId),
    instead of the KeyError -> exception 4 the stock SimCore gives.  A function code
    other than 3, 4, 6 and 16 (coils, FC 22, 23) is exception 1 wherever it points (the
    stock SimCore answers a coil function at an address without coils with exception
    2); a write of one goes to ``on_unserved`` to be logged.  Writes pass ``guard``
    first (writes disabled, client not allowed: exception 1 wherever they point, so a
    refused client cannot map the registers), and a write the map refuses before our
    action sees it (outside the map: exception 2) is logged as the others are."""

    guard: Callable[[int], ExcCodes | None] | None = None
    on_outside: Callable[[int], object] | None = None
    on_unserved: Callable[[int, int], ExcCodes] | None = None

    async def async_getValues(self, device_id, func_code, address, count=1):
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        if func_code not in _SERVED_FCS:
            return ExcCodes.ILLEGAL_FUNCTION
        return await super().async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        if func_code not in _WRITE_FCS:
            if self.on_unserved is not None:
                return self.on_unserved(func_code, address)
            return ExcCodes.ILLEGAL_FUNCTION
        refused = self.guard(address) if self.guard is not None else None
        if refused is not None:
            return refused
        _WRITE_SEEN.set(False)
        result = await super().async_setValues(device_id, func_code, address, values)
        if result == ExcCodes.ILLEGAL_ADDRESS and not _WRITE_SEEN.get() and self.on_outside is not None:
            self.on_outside(address)  # the map refused it before our action saw it
        return result


def _networks(allow: Iterable[str]) -> tuple:
    return tuple(ipaddress.ip_network(a, strict=False) for a in allow)


def peer_allowed(peer: str | None, networks: tuple) -> bool:
    """True if ``peer`` (an IP address string) is in one of ``networks``."""
    if not peer:
        return False
    try:
        ip = ipaddress.ip_address(peer.split("%")[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped:
        ip = ip.ipv4_mapped  # a dual-stack socket reports ::ffff:a.b.c.d
    return any(ip in net for net in networks if net.version == ip.version)


_BIND_ERRORS = {
    errno.EADDRINUSE: "the port is in use by another program (another heliotrack run or simulate --realtime?)",
    errno.EADDRNOTAVAIL: "not an address of this machine",
    errno.EACCES: "permission denied (a port below 1024 needs privileges)",
}


def _why_not_bound(host: str, port: int) -> str | None:
    """Why ``host:port`` cannot be listened on, by trying it: pymodbus logs the bind's
    error and raises only "Could not start listen, please check address."; None when
    the bind works now or fails otherwise."""
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server
            s.bind((host, port))
    except OSError as exc:
        return _BIND_ERRORS.get(exc.errno or 0, exc.strerror or str(exc))
    return None


class SunSpecServer:
    """SunSpec (model 1 + model 601) Modbus TCP server in a daemon thread.

    Parameters
    ----------
    snapshot : callable
        ``snapshot() -> PlantSnapshot``, called on every request (in the server thread;
        must be thread-safe and quick).  The tracker count is fixed by the first call.
    on_override : callable, optional
        ``on_override(OverrideCommand)``, called in the server thread for every accepted
        write, before the client gets its answer.  Must be quick and thread-safe (e.g. put
        the command on a queue).  An exception refuses the write (exception 4).
    host : str
        Address to bind; 127.0.0.1 unless SCADA is elsewhere.
    port : int
        TCP port; 0 picks a free one (see :attr:`port` after :meth:`start`).
    device_address : int
        Modbus unit id answered (model 1 ``DA``); other ids get exception 0x0B.
    writes_enabled : bool
        False (default): every write is refused.
    allow : iterable of str
        Client addresses or networks (``"10.0.0.0/24"``) whose writes are accepted.
    identity : Identity, optional
        Model 1 strings.
    base_address : int
        Address of the ``SunS`` marker.
    """

    def __init__(
        self,
        snapshot: SnapshotFn,
        on_override: OverrideFn | None = None,
        *,
        host: str = "127.0.0.1",
        port: int = 1502,
        device_address: int = 1,
        writes_enabled: bool = False,
        allow: Iterable[str] = ("127.0.0.1",),
        identity: Identity | None = None,
        base_address: int = SUNSPEC_BASE_ADDRESS,
    ):
        self.snapshot = snapshot
        self.on_override = on_override
        self.host = host
        self.requested_port = int(port)
        self.device_address = int(device_address)
        self.writes_enabled = bool(writes_enabled)
        self.allow = tuple(allow)
        self._networks = _networks(self.allow)
        self.identity = identity or Identity(device_address=self.device_address)
        self.base_address = base_address
        self.port: int | None = None
        self.map: SunSpecMap | None = None
        self.stats = {"reads": 0, "writes_accepted": 0, "writes_refused": 0, "errors": 0}
        self._log_budget = _LogBudget()
        self._encoder: Encoder | None = None
        self._controls: ControlTable | None = None
        self._thread = ServerThread(self._make_server, name="sunspec-server")

    @classmethod
    def from_config(
        cls, cfg: SunSpecConfig, snapshot: SnapshotFn, on_override: OverrideFn | None = None, **kw
    ) -> SunSpecServer:
        """Build from a parsed ``[sunspec]`` table (see :func:`parse_sunspec`)."""
        ident = Identity(serial_number=cfg.serial_number, device_address=cfg.device_address)
        return cls(
            snapshot,
            on_override,
            host=cfg.host,
            port=cfg.port,
            device_address=cfg.device_address,
            writes_enabled=cfg.writes_enabled,
            allow=cfg.allow,
            identity=ident,
            **kw,
        )

    # -- lifecycle -------------------------------------------------------------------
    def start(self) -> Self:
        """Build the map from a first snapshot, bind, and serve; returns self."""
        plant = self.snapshot()
        self.map = SunSpecMap(len(plant.trackers), self.base_address)
        self._encoder = Encoder(self.map, self.identity)
        self._controls = ControlTable(self.map)
        self._controls.refresh(plant)
        self._encoder.registers(plant, self._controls.staged, self.base_address, self.map.size)
        try:
            self._thread.start()
        except ServerThreadError as exc:
            why = _why_not_bound(self.host, self.requested_port) or str(exc)
            raise SunSpecServerError(
                f"SunSpec server failed to start on {self.host}:{self.requested_port}: {why}"
            ) from exc
        self.port = self._thread.port
        log.info(
            "SunSpec server on %s:%d, unit %d, %d trackers, writes %s",
            self.host,
            self.port,
            self.device_address,
            self.map.n_trackers,
            f"enabled for {', '.join(self.allow)}" if self.writes_enabled else "disabled",
        )
        return self

    def stop(self) -> None:
        self._thread.stop()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _make_server(self) -> ModbusTcpServer:
        """The pymodbus server (called in the server thread, on its event loop)."""
        assert self.map is not None
        device = SimDevice(
            id=self.device_address,
            simdata=[SimData(self.base_address, count=self.map.size, values=0, datatype=DataType.REGISTERS)],
            action=self._action,
        )
        server = _PeerAwareTcpServer(device, address=(self.host, self.requested_port))
        core = _SingleUnitCore(device)
        core.guard = self._guard
        core.on_outside = lambda address: self._refuse(
            ExcCodes.ILLEGAL_ADDRESS, _PEER.get(), address, "outside the SunSpec map"
        )
        core.on_unserved = lambda fc, address: self._refuse(
            ExcCodes.ILLEGAL_FUNCTION,
            _PEER.get(),
            address,
            f"function code {fc} is not served (6 or 16 write)",
        )
        server.context = core
        return server

    # -- requests --------------------------------------------------------------------
    async def _action(self, fc, start, address, count, registers, set_values):
        """pymodbus SimDevice action: render before reads, police writes."""
        try:
            if set_values is None:
                if fc not in _READ_FCS | _WRITE_FCS:  # reads back after FC 6 are fc 6
                    return ExcCodes.ILLEGAL_FUNCTION
                plant = self.snapshot()
                self._controls.refresh(plant)
                words = self._encoder.registers(plant, self._controls.staged, address, count)
                registers[address - start : address - start + count] = words
                self.stats["reads"] += 1
                return None
            if fc not in _WRITE_FCS:
                return ExcCodes.ILLEGAL_FUNCTION
            _WRITE_SEEN.set(True)
            return self._write(address, [int(v) for v in set_values])
        except Exception:  # a bad snapshot must not kill the server; the client gets exc 4
            self.stats["errors"] += 1
            log.exception("SunSpec request fc=%s address=%s count=%s failed", fc, address, count)
            return ExcCodes.DEVICE_FAILURE

    def _guard(self, address: int) -> ExcCodes | None:
        """Exception 1 for any write of a client that may not write (None: go on)."""
        peer = _PEER.get()
        if not self.writes_enabled:
            return self._refuse(ExcCodes.ILLEGAL_FUNCTION, peer, address, "writes are disabled")
        if not peer_allowed(peer, self._networks):
            return self._refuse(ExcCodes.ILLEGAL_FUNCTION, peer, address, "client not in the allowlist")
        return None

    def _write(self, address: int, words: list[int]) -> ExcCodes | None:
        peer = _PEER.get()
        refused = self._guard(address)
        if refused is not None:
            return refused
        controls = self._controls
        assert controls is not None  # built by start()
        plant = self.snapshot()
        controls.refresh(plant)
        backup = copy.deepcopy(controls.staged)
        try:
            commands = controls.apply_write(plant, address, words, peer or "")
        except WriteRefused as exc:
            return self._refuse(exc.code, peer, address, exc.reason)
        try:
            for cmd in commands:
                if self.on_override is not None:
                    self.on_override(cmd)
        except Exception:
            controls.staged = backup
            self.stats["errors"] += 1
            log.exception("on_override refused a SunSpec write from %s", peer)
            return ExcCodes.DEVICE_FAILURE
        self.stats["writes_accepted"] += 1
        for cmd in commands:
            if self._log_budget.allows(peer):
                log.info("SunSpec override from %s: %s", peer, cmd)
        return None

    def _refuse(self, code: ExcCodes, peer, address: int, reason: str) -> ExcCodes:
        self.stats["writes_refused"] += 1
        if self._log_budget.allows(peer):
            log.warning(
                "SunSpec write at %d from %s refused (exception %d): %s", address, peer, int(code), reason
            )
        return code


class _LogBudget:
    """At most ``per_window`` log lines of writes per client per ``window_s``; the rest are
    counted and said in one line when the client's next window opens (a SCADA loop
    writing a thousand times a second must not fill the plant's log)."""

    def __init__(self, per_window: int = 20, window_s: float = 10.0):
        self.per_window, self.window_s = per_window, window_s
        self._open: dict[str | None, tuple[float, int, int]] = {}  # peer: (start, lines, unsaid)

    def allows(self, peer: str | None) -> bool:
        now = time.monotonic()
        start, lines, unsaid = self._open.get(peer, (-math.inf, 0, 0))
        if now - start >= self.window_s:
            if unsaid:
                log.warning(
                    "SunSpec: %d more writes from %s in %g s were not logged", unsaid, peer, self.window_s
                )
            start, lines, unsaid = now, 0, 0
        ok = lines < self.per_window
        self._open[peer] = (start, lines + ok, unsaid + (not ok))
        return ok
