"""Read a Modbus pyranometer (map in :mod:`firmware_protocol.pyranometer`)."""

from __future__ import annotations

from dataclasses import dataclass

from pymodbus.exceptions import ModbusException

from firmware_protocol import decode
from firmware_protocol.pyranometer import PYR

from ..drives.base import DriveCommError

MAX_PLAUSIBLE_W_M2 = 1600.0  # above the solar constant plus cloud enhancement: a fault


@dataclass(frozen=True)
class IrradianceSample:
    time: float
    ghi_w_m2: float


class ModbusPyranometer:
    """A pyranometer on a (shared) pymodbus asyncio client.

    :meth:`read` raises :class:`DriveCommError` on a link error, a fault status or an
    implausible value, so a bad sample is never used.
    """

    def __init__(self, client, device_id: int, label: str = ""):
        self.client = client
        self.device_id = device_id
        self.label = label or f"pyranometer id {device_id}"

    async def connect(self) -> None:
        if not await self.client.connect():
            raise DriveCommError(f"{self.label}: cannot open the link")

    async def read(self, t: float) -> IrradianceSample:
        first = PYR["PYR_IRRADIANCE"].offset
        last = PYR["PYR_STATUS"].offset
        try:
            rr = await self.client.read_input_registers(first, count=last - first + 1,
                                                        device_id=self.device_id)
        except (ModbusException, OSError) as exc:
            raise DriveCommError(f"{self.label}: {exc}") from None
        if rr.isError():
            raise DriveCommError(f"{self.label}: {rr}")
        words = rr.registers
        status = decode(PYR["PYR_STATUS"], [words[last - first]])
        if status & 0b11:
            raise DriveCommError(f"{self.label}: sensor reports status {status:#06x}")
        ghi = float(decode(PYR["PYR_IRRADIANCE"], [words[0]]))
        if not -10.0 <= ghi <= MAX_PLAUSIBLE_W_M2:
            raise DriveCommError(f"{self.label}: implausible irradiance {ghi} W/m2")
        return IrradianceSample(t, max(ghi, 0.0))

    async def close(self) -> None:
        self.client.close()
