"""A Modbus TCP proxy on 127.0.0.1 that injects faults at the request level.

The emulated gateway (:class:`hil.modbus_server.ModbusServerThread`) serves behind it;
masters connect to the proxy.  Each connection is pumped both ways: requests go through
as they are, every reply is framed by its MBAP header and handed to a
:class:`~hil.wire_faults.WireFaults` (dropped, damaged, split, delayed, or from another
unit).  A unit can also be "down" (its emulator process killed): the connections that
carried it are reset, and a connection that asks it anything is reset at once, until it
is up again.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Self

from .errors import HilError
from .wire_faults import WireFaults

_MBAP = 7  # transaction id, protocol id, length, unit id


class _Connection:
    def __init__(self, writer: asyncio.StreamWriter, upstream: asyncio.StreamWriter):
        self.writer = writer
        self.upstream = upstream
        self.units: set[int] = set()

    def reset(self) -> None:
        for w in (self.writer, self.upstream):
            with contextlib.suppress(Exception):
                w.transport.abort()


class FaultProxy:
    """Forward Modbus TCP from ``127.0.0.1:port`` (0: a free port) to ``upstream_port``.

    Parameters
    ----------
    upstream_port : int
        The emulated server's port on 127.0.0.1.
    faults : WireFaults, optional
        What happens to replies (None: nothing).
    port : int
        Port to listen on (0: any free one; see :attr:`port`).
    """

    def __init__(self, upstream_port: int, faults: WireFaults | None = None, port: int = 0):
        self.upstream_port = upstream_port
        self.faults = faults
        self.port = port
        self.down: set[int] = set()
        self._conns: set[_Connection] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.AbstractServer | None = None
        self._ready = threading.Event()
        self._stopped: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="modbus-tcp-proxy", daemon=True)

    # -- control (any thread) -------------------------------------------------------------
    def start(self) -> Self:
        self._thread.start()
        self._ready.wait(10)
        if self._error is not None or not self._ready.is_set():
            raise HilError(f"TCP fault proxy did not start: {self._error}")
        return self

    def stop(self) -> None:
        loop = self._loop
        if loop is not None and loop.is_running() and self._stopped is not None:
            loop.call_soon_threadsafe(self._stopped.set)
        self._thread.join(5)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def set_down(self, unit: int, down: bool) -> None:
        """Take ``unit`` down (its connections are reset) or bring it back."""
        if down:
            self.down.add(unit)
            self._call(lambda: self._reset(lambda c: unit in c.units))
        else:
            self.down.discard(unit)

    def _call(self, fn: Callable[[], None]) -> None:
        loop = self._loop
        if loop is not None and loop.is_running():
            done = threading.Event()

            def run() -> None:
                try:
                    fn()
                finally:
                    done.set()

            loop.call_soon_threadsafe(run)
            done.wait(5)

    def _reset(self, which: Callable[[_Connection], bool]) -> None:
        for c in list(self._conns):
            if which(c):
                c.reset()
                self._conns.discard(c)

    # -- the proxy's own loop ---------------------------------------------------------------
    def _run(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()
        finally:
            loop.close()

    async def _serve(self) -> None:
        self._stopped = asyncio.Event()
        self._server = await asyncio.start_server(self._accept, "127.0.0.1", self.port, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]
        self._ready.set()
        await self._stopped.wait()
        self._server.close()
        self._reset(lambda c: True)
        with contextlib.suppress(Exception):
            await asyncio.wait_for(self._server.wait_closed(), 2)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        except OSError:
            writer.transport.abort()
            return
        conn = _Connection(writer, up_writer)
        self._conns.add(conn)
        replies = asyncio.ensure_future(self._replies(up_reader, conn))
        try:
            await self._requests(reader, conn)
        finally:
            replies.cancel()
            self._conns.discard(conn)
            conn.reset()

    async def _requests(self, reader: asyncio.StreamReader, conn: _Connection) -> None:
        with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError, OSError):
            while True:
                adu = await _read_adu(reader)
                unit = adu[6]
                conn.units.add(unit)
                if unit in self.down:
                    return  # the unit's process is gone: the connection is reset
                conn.upstream.write(adu)
                await conn.upstream.drain()

    async def _replies(self, reader: asyncio.StreamReader, conn: _Connection) -> None:
        with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError, OSError):
            while True:
                adu = await _read_adu(reader)
                chunks = [(0.0, adu)] if self.faults is None else self.faults.tcp_reply(adu)
                for delay, chunk in chunks:
                    if delay > 0:
                        await asyncio.sleep(delay)
                    conn.writer.write(chunk)
                    await conn.writer.drain()


async def _read_adu(reader: asyncio.StreamReader) -> bytes:
    header = await reader.readexactly(_MBAP)
    n = int.from_bytes(header[4:6], "big")
    return header + (await reader.readexactly(n - 1) if n > 1 else b"")
