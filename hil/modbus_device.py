"""Emulated devices as pymodbus simulator devices, and the datastore core of a multidrop line.

Each device is a pymodbus ``SimDevice`` whose register block is refreshed from, and whose
writes are applied to, a device object with ``read(address, count)`` and
``write(address, values)`` methods (see :class:`hil.drive.firmware.DriveFirmware`); a
:class:`~hil.drive.firmware.FirmwareReject` becomes the Modbus exception it names.
Requests for a slave id nobody here owns are ignored (:class:`MultidropCore`), as on a
real multidrop RS-485 line; so are requests for a device that is switched off
(:class:`DeviceSlot`: fault injection, an emulator killed and restarted).
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Any, Protocol

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.simulator import DataType, SimData, SimDevice
from pymodbus.simulator.simcore import SimCore

from firmware_protocol import REGISTER_SPACE

from .drive.firmware import FirmwareReject

_REGISTER_FCS = {3, 4, 6, 16, 23}


class RegisterDevice(Protocol):
    """What the Modbus server needs of an emulated device: 16-bit register access."""

    def read(self, address: int, count: int) -> list[int]: ...
    def write(self, address: int, values: Sequence[int]) -> None: ...


class DeviceSlot:
    """The place of one device behind a slave id: it can be switched off (it then answers
    nothing, as a device without power) and replaced (a restart with fresh firmware)."""

    def __init__(self, device: RegisterDevice):
        self.device = device
        self.powered = True

    @property
    def response_delay_s(self) -> float:
        return float(getattr(self.device, "response_delay_s", 0.0))

    def read(self, address: int, count: int) -> list[int]:
        return self.device.read(address, count)

    def write(self, address: int, values: Sequence[int]) -> None:
        self.device.write(address, values)


def sim_device(device_id: int, device: RegisterDevice, size: int = REGISTER_SPACE) -> SimDevice:
    """Wrap ``device`` as a pymodbus SimDevice answering FC 3, 4, 6, 16 and 23.

    A device with a ``response_delay_s`` attribute answers that much later (fault
    injection: a slow or hung device).
    """

    async def action(
        fc: int, start: int, address: int, count: int, registers: Any, set_values: Any
    ) -> ExcCodes | None:
        delay = getattr(device, "response_delay_s", 0.0)
        if delay:
            await asyncio.sleep(delay)
        try:
            if fc not in _REGISTER_FCS:
                return ExcCodes.ILLEGAL_FUNCTION
            if set_values is None:  # a read, or the read-back pymodbus does for a write
                words = device.read(address, count)
                registers[address - start : address - start + count] = words
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


class MultidropCore(SimCore):
    """SimCore that raises NoSuchIdException for foreign ids instead of a KeyError, so the
    server stays silent for them (pymodbus's own core answers exception 4); silent too for
    a device whose ``powered`` attribute is false (see :class:`DeviceSlot`)."""

    def __init__(self, devices: list[SimDevice], targets: dict[int, Any] | None = None):
        super().__init__(devices)
        self.targets = targets or {}

    def _check(self, device_id: int) -> None:
        if device_id not in self.devices or not getattr(self.targets.get(device_id), "powered", True):
            raise NoSuchIdException(str(device_id))

    async def async_getValues(self, device_id, func_code, address, count=1):
        self._check(device_id)
        return await super().async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):
        self._check(device_id)
        return await super().async_setValues(device_id, func_code, address, values)
