"""An emulated Modbus anemometer (map in :mod:`firmware_protocol.anemometer`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

from firmware_protocol import encode
from firmware_protocol.anemometer import ANE, ANEMOMETER_DEVICE_TYPE, ANEMOMETER_SPACE, GUST_HOLD_S, SAMPLE_HZ

from .drive.firmware import FirmwareReject
from .wind import WindScript


class Anemometer:
    """A read-only register device reading the world's wind.

    Fault injection: ``fault`` (status bit 0), ``frozen_at`` (the values and the sample
    counter stop at that time), ``override`` (speed, m/s: an out-of-range or absurd value).
    """

    def __init__(self, wind: WindScript, now: Callable[[], float]):
        self.wind = wind
        self.now = now
        self.fault = False
        self.frozen_at: float | None = None
        self.override: float | None = None

    def values(self) -> dict[str, float]:
        t = self.now() if self.frozen_at is None else min(self.now(), self.frozen_at)
        speed = float(self.wind.speed(t)[0]) if self.override is None else self.override
        gust = self.wind.gust(t, GUST_HOLD_S, SAMPLE_HZ) if self.override is None else self.override
        mean = self.wind.mean_10min(t) if self.override is None else self.override
        out_of_range = max(speed, gust, mean) > 75.0
        clip = lambda v: min(max(v, 0.0), 655.0)  # noqa: E731 - the register's range
        return {
            "ANE_DEVICE_TYPE": ANEMOMETER_DEVICE_TYPE,
            "ANE_SPEED": clip(speed),
            "ANE_GUST": clip(gust),
            "ANE_MEAN_10MIN": clip(mean),
            "ANE_DIRECTION": float(self.wind.direction(t)[0]),
            "ANE_SAMPLE_COUNT": int(t * SAMPLE_HZ) % 65536,
            "ANE_STATUS": (1 if self.fault else 0) | (2 if out_of_range else 0),
        }

    def read(self, address: int, count: int) -> list[int]:
        if address < 0 or address + count > ANEMOMETER_SPACE:
            raise FirmwareReject(2, "outside the anemometer's registers")
        words = [0] * ANEMOMETER_SPACE
        for name, value in self.values().items():
            reg = ANE[name]
            words[reg.offset : reg.offset + reg.words] = encode(reg, value)
        return words[address : address + count]

    def write(self, address: int, values: Sequence[int]) -> None:
        raise FirmwareReject(2, "the anemometer has no writable registers")
