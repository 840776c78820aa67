"""Modbus RTU and TCP drive links over pymodbus's asyncio clients (``modbus-rtu``, ``modbus-tcp``)."""

from __future__ import annotations

import time
from collections.abc import Sequence

from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException

from firmware_protocol import (
    AXIS_STRIDE, MAGIC, PROTOCOL_VERSION, Command, Fault, Mode, Status, decode, encode,
    register,
)
from firmware_protocol.codec import axis_block_address, decode_axis

from .base import AxisState, DriveCommError, DriveLink, DriveState, LinkStats, register_backend
from .links import LinkConfig, ModbusRtuLink, ModbusTcpLink

_ID_WORDS = 3
_TARGET = register("TARGET_ANGLE")


class ModbusDrive(DriveLink):
    """A drive on a pymodbus asyncio client (serial RTU or TCP).

    Parameters
    ----------
    client : pymodbus async client (or a shared wrapper of one)
    device_id : int
        Modbus slave id of the drive.
    retries : int
        Extra attempts after a failed transaction.
    label : str
        Used in error messages (``"/dev/ttyUSB0 id 4"``).
    """

    def __init__(self, client, device_id: int, retries: int = 2, label: str = ""):
        self.client = client
        self.device_id = device_id
        self.retries = retries
        self.label = label or f"id {device_id}"
        self.axis_count = 0
        self.stats = LinkStats()
        self._beat = 0

    async def _call(self, what: str, fn, *args, **kwargs):
        last = None
        for attempt in range(self.retries + 1):
            t0 = time.perf_counter()
            self.stats.transactions += 1
            try:
                rr = await fn(*args, device_id=self.device_id, **kwargs)
            except (ModbusException, OSError) as exc:
                last = exc
            else:
                if not rr.isError():
                    self.stats.latencies_s.append(time.perf_counter() - t0)
                    return rr
                last = rr
            self.stats.errors += 1
            if attempt < self.retries:
                self.stats.retries += 1
        raise DriveCommError(f"{self.label}: {what} failed after {self.retries + 1} attempt(s): {last}")

    async def connect(self) -> None:
        if not await self.client.connect():
            raise DriveCommError(f"{self.label}: cannot open the link")
        words = (await self._call("identification read", self.client.read_holding_registers,
                                  0, count=_ID_WORDS)).registers
        if words[0] != MAGIC:
            raise DriveCommError(f"{self.label}: not a heliotrack drive (register 0 = {words[0]:#06x})")
        if words[1] >> 8 != PROTOCOL_VERSION >> 8:
            raise DriveCommError(f"{self.label}: protocol {words[1] >> 8}.x, expected {PROTOCOL_VERSION >> 8}.x")
        if not 1 <= words[2] <= 2:
            raise DriveCommError(f"{self.label}: implausible axis count {words[2]}")
        self.axis_count = words[2]

    async def close(self) -> None:
        self.client.close()

    def _decode_state(self, words: Sequence[int]) -> DriveState:
        axes = []
        try:
            for k in range(self.axis_count):
                v = decode_axis(words, k * AXIS_STRIDE)
                axes.append(AxisState(
                    actual_deg=float(v["ACTUAL_ANGLE"]), target_deg=float(v["TARGET_ANGLE"]),
                    velocity_dps=float(v["VELOCITY"]), status=Status(int(v["STATUS"])),
                    fault=Fault(int(v["FAULT_CODE"])), mode=Mode(int(v["MODE"]))))
        except (ValueError, KeyError) as exc:  # an unknown mode or fault code on the wire
            raise DriveCommError(f"{self.label}: implausible state from the drive: {exc}") from None
        dev = Status(0)
        for a in axes:
            dev |= a.status
        return DriveState(self.axis_count, tuple(axes), dev)

    async def read_state(self) -> DriveState:
        rr = await self._call("state read", self.client.read_holding_registers,
                              axis_block_address(0), count=AXIS_STRIDE * self.axis_count)
        return self._decode_state(rr.registers)

    def _check(self, angles_deg: Sequence[float]) -> None:
        if len(angles_deg) != self.axis_count:
            raise ValueError(f"{self.label}: {len(angles_deg)} targets for {self.axis_count} axes")

    async def write_targets(self, angles_deg: Sequence[float]) -> None:
        self._check(angles_deg)
        for k, angle in enumerate(angles_deg):
            await self._call("target write", self.client.write_registers, _TARGET.address(k),
                             encode(_TARGET, angle))

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        """Axis 1's target by FC16, then axis 0's target and the state read in one FC23."""
        self._check(angles_deg)
        for k in range(1, self.axis_count):
            await self._call("target write", self.client.write_registers, _TARGET.address(k),
                             encode(_TARGET, angles_deg[k]))
        rr = await self._call("target write + state read", self.client.readwrite_registers,
                              read_address=axis_block_address(0),
                              read_count=AXIS_STRIDE * self.axis_count,
                              write_address=_TARGET.address(0),
                              values=encode(_TARGET, angles_deg[0]))
        return self._decode_state(rr.registers)

    async def heartbeat(self) -> None:
        self._beat = (self._beat + 1) & 0xFFFF
        await self._call("heartbeat", self.client.write_register,
                         register("HEARTBEAT").address(), self._beat)

    async def command(self, cmd: Command) -> None:
        await self._call(f"command {cmd.name}", self.client.write_register,
                         register("COMMAND").address(), int(cmd))

    async def configure(self, *, heartbeat_timeout_s=None, soft_limits=None, stow_angles=None) -> None:
        if heartbeat_timeout_s is not None:
            reg = register("HEARTBEAT_TIMEOUT")
            await self._call("configure", self.client.write_registers, reg.address(),
                             encode(reg, heartbeat_timeout_s))
        lo_reg, hi_reg = register("SOFT_LIMIT_MIN"), register("SOFT_LIMIT_MAX")
        for k, (lo, hi) in enumerate(soft_limits or ()):
            await self._call("configure", self.client.write_registers, lo_reg.address(k),
                             encode(lo_reg, lo) + encode(hi_reg, hi))
        reg = register("STOW_ANGLE")
        for k, angle in enumerate(stow_angles or ()):
            await self._call("configure", self.client.write_registers, reg.address(k),
                             encode(reg, angle))

    async def read_register(self, name: str, axis: int | None = None) -> float | int:
        reg = register(name)
        rr = await self._call(f"read {name}", self.client.read_holding_registers,
                              reg.address(axis), count=reg.words)
        return decode(reg, rr.registers)


class _SharedSerialClient:
    """One client per serial port, shared by every drive on that RS-485 line.

    pymodbus locks a port exclusively, and a multidrop line has one master anyway; the
    client serialises requests itself.  The port closes when its last drive closes.
    """

    _open: dict[str, "_SharedSerialClient"] = {}

    def __init__(self, port: str, baudrate: int, timeout_s: float):
        self.client = AsyncModbusSerialClient(port, baudrate=baudrate, timeout=timeout_s,
                                              retries=0, reconnect_delay=0)
        self.port = port
        self.users = 0

    @classmethod
    def acquire(cls, port: str, baudrate: int, timeout_s: float) -> "_SharedSerialClient":
        shared = cls._open.get(port)
        if shared is None:
            shared = cls._open[port] = cls(port, baudrate, timeout_s)
        shared.users += 1
        return shared

    def __getattr__(self, name):
        return getattr(self.client, name)

    async def connect(self) -> bool:
        return self.client.connected or await self.client.connect()

    def close(self) -> None:
        self.users -= 1
        if self.users <= 0:
            self.client.close()
            self._open.pop(self.port, None)


def shared_client(kind: str, *, port: str | int = "", host: str = "127.0.0.1",
                  baudrate: int = 115200, timeout_s: float = 0.5):
    """A pymodbus asyncio client for a sensor on a link (shared with the drives on RTU)."""
    if kind == "modbus-rtu":
        return _SharedSerialClient.acquire(str(port), baudrate, timeout_s)
    if kind == "modbus-tcp":
        return AsyncModbusTcpClient(host, port=int(port), timeout=timeout_s, retries=0,
                                    reconnect_delay=0)
    raise ValueError(f"no Modbus client for link kind {kind!r}")


def _rtu(port: str, device_id: int, baudrate: int = 115200, timeout_s: float = 0.5,
         retries: int = 2, **_) -> ModbusDrive:
    client = _SharedSerialClient.acquire(port, baudrate, timeout_s)
    return ModbusDrive(client, device_id, retries, label=f"{port} id {device_id}")


def _tcp(host: str, port: int, device_id: int, timeout_s: float = 0.5, retries: int = 2,
         **_) -> ModbusDrive:
    client = AsyncModbusTcpClient(host, port=port, timeout=timeout_s, retries=0,
                                  reconnect_delay=0)
    return ModbusDrive(client, device_id, retries, label=f"{host}:{port} id {device_id}")


class ModbusRtuDrive(ModbusDrive):
    """A drive on a Modbus RTU line (link kind ``modbus-rtu``)."""

    config_type = ModbusRtuLink

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> "ModbusRtuDrive":
        assert isinstance(link, ModbusRtuLink)
        client = _SharedSerialClient.acquire(link.port, link.baudrate, link.timeout_s)
        return cls(client, device_id, link.retries, label=f"{link.port} id {device_id}")


class ModbusTcpDrive(ModbusDrive):
    """A drive behind Modbus TCP (link kind ``modbus-tcp``)."""

    config_type = ModbusTcpLink

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> "ModbusTcpDrive":
        assert isinstance(link, ModbusTcpLink)
        client = AsyncModbusTcpClient(link.host, port=link.tcp_port, timeout=link.timeout_s,
                                      retries=0, reconnect_delay=0)
        return cls(client, device_id, link.retries,
                   label=f"{link.host}:{link.tcp_port} id {device_id}")


register_backend("modbus-rtu", _rtu)
register_backend("modbus-tcp", _tcp)
