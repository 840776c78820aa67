"""Bright things that are not the sun, each made to fool a brightest-blob detector.

* :class:`SpecularReflection`: the sun mirrored by a distant flat surface (a window, water,
  a neighbouring panel): a copy of the sun's glare at a fixed direction, ``strength`` times
  as bright.  At ``strength`` ~1 it is as large as the sun's saturated disk.  A distant
  reflector can stay lit while a cloud hides the sun from the camera, so by default it
  does not follow the camera's sun transmittance (``follows_sun=False``).
* :class:`AircraftGlint`: a small saturated point that moves across the sky.
* :class:`FlareGhost`: the lens's internal reflection of the sun: a soft, tinted disk on the
  line from the sun's image through the image centre, on the far side; present only while
  the sun shines into the lens.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SpecularReflection:
    az_deg: float
    el_deg: float
    strength: float = 0.8
    follows_sun: bool = False
    kind: str = "reflection"

    def direction_enu(self, t: float) -> np.ndarray:
        return _azel(self.az_deg, self.el_deg)


@dataclass(frozen=True)
class AircraftGlint:
    """Starts at (az0, el0) at time ``t0`` and moves at (daz, del) deg/s; ``radius_px`` of
    its saturated spot; visible for ``duration_s``."""

    az0_deg: float
    el0_deg: float
    t0: float
    daz_dps: float = 0.05
    del_dps: float = 0.01
    radius_px: float = 1.5
    duration_s: float = 600.0
    kind: str = "glint"

    def direction_enu(self, t: float) -> np.ndarray | None:
        dt = t - self.t0
        if not 0.0 <= dt <= self.duration_s:
            return None
        return _azel(self.az0_deg + self.daz_dps * dt, self.el0_deg + self.del_dps * dt)


@dataclass(frozen=True)
class FlareGhost:
    """``position`` k: the ghost's centre is ``c - k (p_sun - c)`` with c the principal
    point; ``radius_px``; ``level`` peak signal (full scale = 1; > 1 saturates the core);
    ``tint`` (R, G, B)."""

    position: float = 0.7
    radius_px: float = 9.0
    level: float = 1.3
    tint: tuple[float, float, float] = (0.75, 1.0, 0.8)
    kind: str = "ghost"


def _azel(az_deg: float, el_deg: float) -> np.ndarray:
    a, e = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])


def soft_disk(dist_px: np.ndarray, radius_px: float, soft_px: float = 1.2) -> np.ndarray:
    """1 inside, 0 outside, a linear ramp of ``soft_px`` across the rim (anti-aliased)."""
    return np.clip((radius_px - dist_px) / soft_px + 0.5, 0.0, 1.0).astype(np.float32)


def glint_signal(dist_px: np.ndarray, radius_px: float) -> np.ndarray:
    """A point source's saturated spot: a Gaussian core that crosses full scale at
    ``radius_px`` and a faint PSF wing."""
    sigma = max(radius_px, 0.5) / np.sqrt(2.0 * np.log(4.0))  # = 1 at radius_px for peak 4
    return (
        4.0 * np.exp(-0.5 * (dist_px / sigma) ** 2) + 0.05 / (1.0 + (dist_px / (3 * radius_px)) ** 2)
    ).astype(np.float32)
