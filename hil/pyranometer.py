"""An emulated Modbus pyranometer: the sky's GHI with the instrument's imperfections."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from firmware_protocol import encode
from firmware_protocol.pyranometer import PYR, PYRANOMETER_DEVICE_TYPE, PYRANOMETER_SPACE

from .drive.firmware import FirmwareReject


class Pyranometer:
    """A read-only register device (see :mod:`firmware_protocol.pyranometer`).

    Parameters
    ----------
    ghi_at : callable
        POSIX time -> true global horizontal irradiance, W/m2.
    now : callable
        Current time, POSIX s.
    noise_w_m2 : float
        One-sigma measurement noise (class A instruments: a few W/m2).
    seed : int
    """

    def __init__(
        self,
        ghi_at: Callable[[float], float],
        now: Callable[[], float],
        noise_w_m2: float = 2.0,
        seed: int = 0,
    ):
        self.ghi_at = ghi_at
        self.now = now
        self.noise = noise_w_m2
        self.rng = np.random.default_rng(seed)
        self.fault = False  # fault injection: the sensor reports a fault status

    def values(self) -> dict[str, float]:
        g = float(self.ghi_at(self.now()))
        g = max(g + self.rng.normal(0, self.noise), 0.0) if g > 0 else 0.0
        return {
            "PYR_DEVICE_TYPE": PYRANOMETER_DEVICE_TYPE,
            "PYR_IRRADIANCE": round(g),
            "PYR_IRRADIANCE_RAW": round(g * 1.01),
            "PYR_BODY_TEMPERATURE": 25.0,
            "PYR_STATUS": 1 if self.fault else 0,
        }

    def read(self, address: int, count: int) -> list[int]:
        if address < 0 or address + count > PYRANOMETER_SPACE:
            raise FirmwareReject(2, "outside the pyranometer's registers")
        words = [0] * PYRANOMETER_SPACE
        for name, value in self.values().items():
            reg = PYR[name]
            words[reg.offset : reg.offset + reg.words] = encode(reg, value)
        return words[address : address + count]

    def write(self, address: int, values: Sequence[int]) -> None:
        raise FirmwareReject(2, "the pyranometer has no writable registers")
