"""What a sequence of frames says about its bright things: the sun moves like the sun.

The sun crosses the sky at 15.04 deg/h times cos(declination), between 0.23 and 0.25 deg
per minute, whatever the site.  A distractor does not: a reflection in a window stands
still, an aircraft's glint moves degrees per minute, a lens ghost follows the sun's image
mirrored through the image centre.  Without the site (no ephemeris) these vetoes keep
such things from being reported as the sun:

* **static**: a sun-like glare found again where one was five or more minutes ago, within a
  quarter of the sun's least motion since (the sun would have moved at least 1.1 deg);
* **shrunk**: a glare less than half the size of the sun accepted in the last hour (a glint,
  or a sun so dimmed by cloud that its direction is poor anyway).

Among several sun-like glares of similar size, one whose motion since an earlier frame
matches the sun's rate is preferred.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

SUN_RATE_DEG_PER_MIN = (0.22, 0.26)


def _deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(np.dot(a, b), -1.0, 1.0))))


class GlareHistory:
    """Recent sun-like glares of a sequence: (time, [(direction, radius deg), ...])."""

    def __init__(
        self,
        keep_s: float = 1800.0,
        static_after_s: float = 300.0,
        tol_deg: float = 0.3,
        shrink: float = 0.5,
        shrink_memory_s: float = 3600.0,
    ):
        self.keep_s = keep_s
        self.static_after_s = static_after_s
        self.tol_deg = tol_deg
        self.shrink = shrink
        self.shrink_memory_s = shrink_memory_s
        self.frames: deque[tuple[float, list[tuple[np.ndarray, float]]]] = deque()
        self.sun_radius: tuple[float, float] | None = None  # (time, radius of the last accepted)

    def clear(self) -> None:
        self.frames.clear()
        self.sun_radius = None

    def add(self, t: float, glares: list[tuple[np.ndarray, float]]) -> None:
        self.frames.append((t, glares))
        while self.frames and t - self.frames[0][0] > self.keep_s:
            self.frames.popleft()

    def accepted(self, t: float, radius_deg: float) -> None:
        self.sun_radius = (t, radius_deg)

    def is_static(self, t: float, d: np.ndarray) -> bool:
        """Seen at (nearly) the same place at least ``static_after_s`` ago."""
        for t0, glares in self.frames:
            dt_min = (t - t0) / 60.0
            if t - t0 < self.static_after_s:
                continue
            limit = SUN_RATE_DEG_PER_MIN[0] * dt_min / 4.0
            if any(_deg(d, g) < limit for g, _ in glares):
                return True
        return False

    def is_shrunk(self, t: float, radius_deg: float) -> bool:
        if self.sun_radius is None or t - self.sun_radius[0] > self.shrink_memory_s:
            return False
        return radius_deg < self.shrink * self.sun_radius[1]

    def moves_like_the_sun(self, t: float, d: np.ndarray) -> bool:
        """An earlier glare lies at the sun's displacement for the time elapsed."""
        lo, hi = SUN_RATE_DEG_PER_MIN
        for t0, glares in self.frames:
            dt_min = (t - t0) / 60.0
            if dt_min < 2.0:
                continue
            for g, _ in glares:
                dist = _deg(d, g)
                if lo * dt_min - self.tol_deg <= dist <= hi * dt_min + self.tol_deg:
                    return True
        return False
