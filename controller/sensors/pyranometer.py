"""Read a Modbus pyranometer (map in :mod:`firmware_protocol.pyranometer`)."""

from __future__ import annotations

from dataclasses import dataclass

from firmware_protocol import decode
from firmware_protocol.pyranometer import PYR

from ..drives.base import DriveCommError
from .modbus_sensor import ModbusSensor

MAX_PLAUSIBLE_W_M2 = 1600.0  # above the solar constant plus cloud enhancement: a fault
_FIRST = PYR["PYR_IRRADIANCE"].offset
_LAST = PYR["PYR_STATUS"].offset


@dataclass(frozen=True)
class IrradianceSample:
    """One reading: POSIX time (s) and global horizontal irradiance (W/m2)."""

    time: float
    ghi_w_m2: float


class ModbusPyranometer(ModbusSensor):
    """A pyranometer (map in :mod:`firmware_protocol.pyranometer`).

    :meth:`read` raises :class:`DriveCommError` on a link error (after the link's retries),
    a fault status or an implausible value, so a bad sample is never used.
    """

    kind = "pyranometer"

    async def read(self, t: float) -> IrradianceSample:
        """The irradiance now, stamped ``t`` (POSIX s)."""
        words = await self.read_block(_FIRST, _LAST - _FIRST + 1, "irradiance read")
        status = int(decode(PYR["PYR_STATUS"], [words[_LAST - _FIRST]]))
        if status & 0b11:
            raise DriveCommError(f"{self.label}: sensor reports status {status:#06x}")
        ghi = float(decode(PYR["PYR_IRRADIANCE"], [words[0]]))
        if not -10.0 <= ghi <= MAX_PLAUSIBLE_W_M2:
            raise DriveCommError(f"{self.label}: implausible irradiance {ghi} W/m2")
        return IrradianceSample(t, max(ghi, 0.0))
