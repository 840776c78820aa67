"""Records passed between sun sensors, the sun-path filter and the setpoint logic.

Directions are unit vectors in topocentric ENU (x East, y North, z Up) unless a field says
otherwise; azimuth is clockwise from true north (0 N, 90 E) and elevation is above the
horizon, both in degrees, like pvlib.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


def azel_to_enu(az_deg, el_deg) -> np.ndarray:
    """Azimuth/elevation (deg) -> unit vector(s) in ENU, shape (..., 3)."""
    az = np.radians(np.asarray(az_deg, dtype=float))
    el = np.radians(np.asarray(el_deg, dtype=float))
    ce = np.cos(el)
    return np.stack([ce * np.sin(az), ce * np.cos(az), np.sin(el)], axis=-1)


def enu_to_azel(v) -> tuple[np.ndarray, np.ndarray]:
    """ENU vector(s) (any length) -> (azimuth deg in [0, 360), elevation deg)."""
    v = np.asarray(v, dtype=float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    az = np.degrees(np.arctan2(x, y)) % 360.0
    el = np.degrees(np.arctan2(z, np.hypot(x, y)))
    return az, el


def angle_between_deg(a, b) -> np.ndarray:
    """Angle (deg) between vectors ``a`` and ``b`` (broadcasting), robust near 0 and 180."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


class EstimateSource(str, Enum):
    OBSERVED = "observed"
    PREDICTED = "predicted"
    EPHEMERIS = "ephemeris"


@dataclass(frozen=True)
class SunObservation:
    """One measurement of the sun's direction by a sensor.

    Attributes
    ----------
    time : float
        POSIX seconds (UTC) at which the frame or sample was taken.
    az_deg, el_deg : float
        Direction, degrees.  In ENU when ``frame == "enu"``; in the sensor's model frame
        (not levelled or not azimuth-aligned) when ``frame == "model"``.
    sigma_deg : float
        One-sigma angular uncertainty, degrees.
    frame : str
        ``"enu"`` or ``"model"``.
    quality : tuple of str
        Flags such as ``"several_candidates"``; empty when clean.
    sensor : str
        Which sensor produced it (``"hotspot"``, ``"fisheye"``, ``"csv"``...).
    """

    time: float
    az_deg: float
    el_deg: float
    sigma_deg: float = 0.3
    frame: str = "enu"
    quality: tuple[str, ...] = ()
    sensor: str = "unknown"

    @property
    def direction(self) -> np.ndarray:
        return azel_to_enu(self.az_deg, self.el_deg)


@dataclass(frozen=True)
class SunEstimate:
    """The controller's belief about the sun's direction at ``time``.

    ``covariance`` is the 2x2 covariance of (azimuth, elevation) in deg^2; ``source`` says
    whether it came from a fresh observation, the filter's prediction or the ephemeris.
    """

    time: float
    az_deg: float
    el_deg: float
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))
    source: EstimateSource = EstimateSource.EPHEMERIS

    @property
    def direction(self) -> np.ndarray:
        return azel_to_enu(self.az_deg, self.el_deg)

    @property
    def sigma_deg(self) -> float:
        """Angular one-sigma (deg), azimuth scaled by cos(elevation)."""
        c = np.cos(np.radians(self.el_deg))
        return float(np.sqrt(max(self.covariance[0, 0] * c * c + self.covariance[1, 1], 0.0)))
