"""Read a Modbus anemometer (map in :mod:`firmware_protocol.anemometer`)."""

from __future__ import annotations

from typing import Any

from firmware_protocol import decode
from firmware_protocol.anemometer import ANE, ANE_STATUS_BAD

from ..drives.base import DriveCommError
from ..weather import WindSample
from .modbus_sensor import ModbusSensor

#: Above this the reading is out of any anemometer's range (and of any storm): a fault.
MAX_PLAUSIBLE_M_S = 75.0
_FIRST = ANE["ANE_SPEED"].offset
_LAST = ANE["ANE_STATUS"].offset


class ModbusAnemometer(ModbusSensor):
    """An anemometer.

    :meth:`read` raises :class:`DriveCommError` on a link error, a fault or out-of-range
    status, an implausible value, or a frozen sensor (the sample counter did not move
    between two reads more than a second apart), so a bad sample is never used: the wind
    monitor counts it as silence.
    """

    kind = "anemometer"

    def __init__(self, client: Any, device_id: int, label: str = "", retries: int = 0):
        super().__init__(client, device_id, label, retries)
        self._last_count: tuple[float, int] | None = None

    async def read(self, t: float) -> WindSample:
        """The wind now, stamped ``t`` (POSIX s, the controller's clock)."""
        words = await self.read_block(_FIRST, _LAST - _FIRST + 1, "wind read")

        def value(name: str) -> float:
            reg = ANE[name]
            return float(decode(reg, words[reg.offset - _FIRST : reg.offset - _FIRST + reg.words]))

        status = int(value("ANE_STATUS"))
        if status & ANE_STATUS_BAD:
            raise DriveCommError(f"{self.label}: sensor reports status {status:#06x}")
        speed, gust, mean = value("ANE_SPEED"), value("ANE_GUST"), value("ANE_MEAN_10MIN")
        if not all(0.0 <= v <= MAX_PLAUSIBLE_M_S for v in (speed, gust, mean)):
            raise DriveCommError(
                f"{self.label}: implausible wind {speed:g} / {gust:g} / "
                f"{mean:g} m/s (speed / gust / 10-min mean)"
            )
        count = int(value("ANE_SAMPLE_COUNT"))
        last = self._last_count
        self._last_count = (t, count)
        if last is not None and count == last[1] and t - last[0] > 1.0:
            raise DriveCommError(f"{self.label}: frozen (sample counter stuck at {count})")
        return WindSample(t, speed, gust, mean)
