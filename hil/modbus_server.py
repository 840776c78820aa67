"""Serve emulated devices over Modbus RTU (serial URL or pty) or TCP, with pymodbus.

The server runs on its own asyncio loop in a daemon thread
(:class:`firmware_protocol.server_thread.ServerThread`), so the caller's code stays
synchronous; what is the emulator's own is the datastore: devices as
:func:`~hil.modbus_device.sim_device` and the multidrop core that keeps foreign ids
silent (:mod:`hil.modbus_device`).
"""

from __future__ import annotations

import logging
from typing import Self

from pymodbus.server import ModbusBaseServer, ModbusSerialServer, ModbusTcpServer

from firmware_protocol.server_thread import ServerThread, ServerThreadError

from .errors import HilError
from .modbus_device import MultidropCore, RegisterDevice, sim_device

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

__all__ = ["ModbusServerThread", "RegisterDevice", "sim_device"]


class ModbusServerThread(ServerThread):
    """Emulated devices behind one pymodbus server, in a daemon thread.

    Parameters
    ----------
    devices : dict
        Slave id -> device with ``read``/``write``.
    serial_url : str, optional
        Serve Modbus RTU on this pyserial URL (``ptyfd://N`` for a pty master).
    tcp : (host, port), optional
        Serve Modbus TCP here instead.  Port 0 picks a free port (see :attr:`tcp_port`).
    baudrate : int
        Line speed, bit/s (RTU).
    parity : {"N", "E", "O"}
        Parity (RTU).
    stopbits : {1, 2}
        Stop bits (RTU).
    """

    def __init__(
        self,
        devices: dict[int, RegisterDevice],
        *,
        serial_url: str | None = None,
        tcp: tuple[str, int] | None = None,
        baudrate: int = 115200,
        parity: str = "N",
        stopbits: int = 1,
    ):
        if (serial_url is None) == (tcp is None):
            raise HilError("serve either on a serial URL or on TCP, not both")
        super().__init__(self._make_server, name="modbus-server")
        self.devices = devices
        self.serial_url = serial_url
        self.tcp = tcp
        self.baudrate, self.parity, self.stopbits = baudrate, parity, stopbits

    @property
    def tcp_port(self) -> int | None:
        """The TCP port served (after :meth:`start`; None on a serial line)."""
        return self.port

    def start(self) -> Self:
        try:
            super().start()
        except ServerThreadError as exc:
            raise HilError(f"Modbus server failed to start: {exc}") from exc
        return self

    def __enter__(self) -> Self:
        return self.start()

    def _make_server(self) -> ModbusBaseServer:
        sims = [sim_device(i, d) for i, d in self.devices.items()]
        server: ModbusBaseServer
        if self.serial_url is not None:
            server = ModbusSerialServer(
                sims,
                port=self.serial_url,
                baudrate=self.baudrate,
                parity=self.parity,
                stopbits=self.stopbits,
                ignore_missing_devices=True,
            )
        else:
            assert self.tcp is not None
            server = ModbusTcpServer(sims, address=self.tcp, ignore_missing_devices=True)
        server.context = MultidropCore(sims)
        return server
