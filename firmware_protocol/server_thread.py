"""A pymodbus server on its own asyncio loop in a daemon thread.

Both Modbus servers of heliotrack run this way, so the code around them stays synchronous:
the emulated drives and sensors (``hil.modbus_server``) and the northbound SunSpec server
(``controller.sunspec.server``).  They cannot import each other, so the thread lives here,
in the package both import; each side builds its own pymodbus server (datastore, request
handler, write policy) in the factory it passes.  Imports only pymodbus.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from typing import Self

from pymodbus.server import ModbusBaseServer, ModbusTcpServer

__all__ = ["ServerThread", "ServerThreadError"]


class ServerThreadError(RuntimeError):
    """The server did not start (address in use, bad serial URL, timeout); the cause is
    chained."""


class ServerThread:
    """Run the pymodbus server ``factory()`` builds on a private event loop in a daemon
    thread.

    Parameters
    ----------
    factory : callable
        Returns the (not yet serving) pymodbus server.  Called in the thread, with its
        event loop running, because pymodbus binds a server to the loop it is made in.
    name : str
        Thread name (shows in debuggers and thread dumps).
    start_timeout_s : float
        How long :meth:`start` waits for the server to listen, s.
    """

    def __init__(
        self,
        factory: Callable[[], ModbusBaseServer],
        *,
        name: str = "modbus-server",
        start_timeout_s: float = 10.0,
    ):
        self.factory = factory
        self.start_timeout_s = start_timeout_s
        #: The TCP port the server listens on (after :meth:`start`; None for serial).
        self.port: int | None = None
        self.server: ModbusBaseServer | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> Self:
        """Start serving; return once the server listens.

        Raises
        ------
        ServerThreadError
            The factory or pymodbus failed (the cause is chained), or the server did not
            listen within ``start_timeout_s``.
        """
        self._thread.start()
        self._ready.wait(self.start_timeout_s)
        if self._error is not None:
            raise ServerThreadError(str(self._error) or type(self._error).__name__) from self._error
        if not self._ready.is_set():
            raise ServerThreadError(f"not listening within {self.start_timeout_s:g} s")
        return self

    def stop(self) -> None:
        """Shut the server down and end the thread (quietly if it never started)."""
        if self._loop is not None and self.server is not None and self._loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self.server.shutdown(), self._loop)
            with contextlib.suppress(Exception):  # already closing: nothing left to release
                fut.result(5)
        if self._thread.is_alive():
            self._thread.join(5)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported to start()
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _serve(self) -> None:
        self.server = server = self.factory()
        await server.serve_forever(background=True)
        if isinstance(server, ModbusTcpServer):
            transport = server.transport
            sock = (
                transport.sockets[0] if hasattr(transport, "sockets") else transport.get_extra_info("socket")
            )
            self.port = sock.getsockname()[1]
        self._ready.set()
        await server.serving
