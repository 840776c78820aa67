"""Emulated devices as pymodbus simulator devices, and the datastore core of a multidrop line.

Each device is a pymodbus ``SimDevice`` whose register block is refreshed from, and whose
writes are applied to, a device object with ``read(address, count)`` and
``write(address, values)`` methods (see :class:`hil.drive.firmware.DriveFirmware`); a
:class:`~hil.drive.firmware.FirmwareReject` becomes the Modbus exception it names.
Requests for a slave id nobody here owns are ignored (:class:`MultidropCore`), as on a
real multidrop RS-485 line.
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
    server stays silent for them (pymodbus's own core answers exception 4)."""

    async def async_getValues(self, device_id, func_code, address, count=1):  # type: ignore[no-untyped-def]
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        return await super().async_getValues(device_id, func_code, address, count)

    async def async_setValues(self, device_id, func_code, address, values):  # type: ignore[no-untyped-def]
        if device_id not in self.devices:
            raise NoSuchIdException(device_id)
        return await super().async_setValues(device_id, func_code, address, values)
