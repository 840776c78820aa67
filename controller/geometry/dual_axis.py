"""Dual-axis (azimuth/elevation) trackers: the panel normal points at the sun."""

from __future__ import annotations

import math


def wrap_into_range(angle_deg: float, lo: float, hi: float, near: float | None = None) -> float:
    """Represent ``angle_deg`` (mod 360) inside [lo, hi]; clamp if no representative fits.

    When several representatives fit (a range wider than 360 deg), the one closest to
    ``near`` (the current axis angle) wins, so the axis never unwinds needlessly.
    """
    base = angle_deg % 360.0
    candidates = [
        base + 360.0 * k for k in range(math.floor((lo - base) / 360.0), math.ceil((hi - base) / 360.0) + 1)
    ]
    inside = [c for c in candidates if lo - 1e-9 <= c <= hi + 1e-9]
    if inside:
        ref = near if near is not None else (lo + hi) / 2
        return min(inside, key=lambda c: abs(c - ref))

    # Outside the travel: clamp to the nearer end (angular distance).
    def dist(end: float) -> float:
        return abs((base - end + 180.0) % 360.0 - 180.0)

    return lo if dist(lo) <= dist(hi) else hi


def dual_axis_setpoint(
    sun_az_deg: float,
    sun_el_deg: float,
    azimuth_limits: tuple[float, float] = (0.0, 360.0),
    elevation_limits: tuple[float, float] = (0.0, 90.0),
    current_az_deg: float | None = None,
) -> tuple[float, float]:
    """Axis angles (azimuth axis, elevation axis) in degrees that face the sun.

    Parameters
    ----------
    sun_az_deg : float
        Sun azimuth, degrees clockwise from north.
    sun_el_deg : float
        Sun apparent elevation, degrees.
    azimuth_limits, elevation_limits : (float, float)
        Axis travel, degrees.
    current_az_deg : float, optional
        Present azimuth axis angle, to choose among equivalent representatives.
    """
    az = wrap_into_range(sun_az_deg, *azimuth_limits, near=current_az_deg)
    el = min(max(sun_el_deg, elevation_limits[0]), elevation_limits[1])
    return az, el
