"""Serve emulated devices over Modbus RTU (serial URL or pty) or TCP, with pymodbus.

Each device is a pymodbus ``SimDevice`` whose register block is refreshed from, and whose
writes are applied to, a device object with ``read(address, count)`` and
``write(address, values)`` methods (see :class:`hil.drive.firmware.DriveFirmware`).  The
server runs its own asyncio loop in a daemon thread, so the caller's code stays
synchronous.  Requests for a slave id nobody here owns are ignored, as on a real
multidrop RS-485 line.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from typing import Protocol, Sequence

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simcore import SimCore

from firmware_protocol import REGISTER_SPACE

from .drive.firmware import FirmwareReject
from .errors import HilError

logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

_REGISTER_FCS = {3, 4, 6, 16, 23}


class RegisterDevice(Protocol):
    def read(self, address: int, count: int) -> list[int]: ...
    def write(self, address: int, values: Sequence[int]) -> None: ...


def sim_device(device_id: int, device: RegisterDevice, size: int = REGISTER_SPACE) -> SimDevice:
    """Wrap ``device`` as a pymodbus SimDevice answering FC 3, 4, 6, 16 and 23."""

    async def action(fc, start, address, count, registers, set_values):
        delay = getattr(device, "response_delay_s", 0.0)
        if delay:  # fault injection: a slow or hung device answers late (or never)
            await asyncio.sleep(delay)
        try:
            if fc not in _REGISTER_FCS:
                return ExcCodes.ILLEGAL_FUNCTION
            if set_values is None:   # a read, or the read-back pymodbus does for a write
                words = device.read(address, count)
                registers[address - start: address - start + count] = words
            else:
                device.write(address, [int(v) for v in set_values])
        except FirmwareReject as exc:
            return ExcCodes(exc.code)
        return None

    return SimDevice(
        id=device_id,
        simdata=[SimData(0, count=size, values=0, datatype=DataType.REGISTERS)],
        action=action,
    )


class _MultidropCore(SimCore):
    """SimCore that raises NoSuchIdException for foreign ids instead of a KeyError."""

    async def async_getValues(self, device_id, func_code, address, count=1):
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        return await super().async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        return await super().async_setValues(device_id, func_code, address, values)


class ModbusServerThread:
    """A pymodbus server on its own event loop in a daemon thread.

    Parameters
    ----------
    devices : dict
        Slave id -> device with ``read``/``write``.
    serial_url : str, optional
        Serve Modbus RTU on this pyserial URL (``ptyfd://N`` for a pty master).
    tcp : (host, port), optional
        Serve Modbus TCP here instead.  Port 0 picks a free port (see :attr:`tcp_port`).
    """

    def __init__(self, devices: dict[int, RegisterDevice], *, serial_url: str | None = None,
                 tcp: tuple[str, int] | None = None, baudrate: int = 115200):
        if (serial_url is None) == (tcp is None):
            raise HilError("serve either on a serial URL or on TCP, not both")
        self.devices = devices
        self.serial_url = serial_url
        self.tcp = tcp
        self.baudrate = baudrate
        self.tcp_port: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="modbus-server", daemon=True)

    def start(self) -> "ModbusServerThread":
        self._thread.start()
        self._ready.wait(10)
        if self._error:
            raise HilError(f"Modbus server failed to start: {self._error}") from self._error
        if not self._ready.is_set():
            raise HilError("Modbus server did not start within 10 s")
        return self

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as exc:  # reported to start()
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        sims = [sim_device(i, d) for i, d in self.devices.items()]
        if self.serial_url is not None:
            self._server = ModbusSerialServer(
                sims, port=self.serial_url, baudrate=self.baudrate,
                ignore_missing_devices=True)
        else:
            self._server = ModbusTcpServer(sims, address=self.tcp, ignore_missing_devices=True)
        self._server.context = _MultidropCore(sims)
        await self._server.serve_forever(background=True)
        if self.tcp is not None:
            self.tcp_port = self._find_tcp_port()
        self._ready.set()
        await self._server.serving

    def _find_tcp_port(self) -> int:
        transport = self._server.transport
        sock = transport.sockets[0] if hasattr(transport, "sockets") else transport.get_extra_info("socket")
        return sock.getsockname()[1]

    def stop(self) -> None:
        if self._loop and self._server and self._loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            try:
                fut.result(5)
            except Exception:
                pass
        self._thread.join(5)

    def __enter__(self) -> "ModbusServerThread":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
