"""Dual-axis (azimuth/elevation) trackers: the panel normal points at the sun.

Azimuth travel wider than one turn, and where it unwinds
--------------------------------------------------------
Where the sun stays up through midnight (latitudes beyond :data:`MIDNIGHT_SUN_LATITUDE_DEG`),
its azimuth turns a whole circle a day, so an axis of any finite travel must unwind a turn
once a day or so.  Following the nearest representative alone puts that unwinding wherever
the hard limit falls: an audit at Tromso in June with ``[-90, 450]`` unwound at 05:23 UTC
with the sun 25 deg up, six minutes of a 1 deg/s drive away from the sun.  The sun is
lowest where it crosses the meridian below the pole (due north north of the equator, due
south south of it), so there the turn costs least: with a ``seam`` the axis's day is the
one turn from the seam to the seam plus 360 deg (placed in the middle of the travel), and
it unwinds :data:`SEAM_HYSTERESIS_DEG` past the seam, so that a sun estimate that jitters
about the seam does not swing the axis back and forth.  Closer to the equator the seam is
not used: there the noon sun can cross the north (the summer tropics), high in the sky.
"""

from __future__ import annotations

import math

__all__ = [
    "MIDNIGHT_SUN_LATITUDE_DEG",
    "SEAM_HYSTERESIS_DEG",
    "dual_axis_setpoint",
    "lowest_sun_azimuth",
    "wrap_into_range",
]

#: Beyond this latitude (deg, either sign) the sun can stay up through midnight: 90 deg less
#: the greatest declination (23.44) and the refraction and semi-diameter at the horizon (0.83).
MIDNIGHT_SUN_LATITUDE_DEG = 65.0

#: How far (deg of azimuth) past the seam the axis keeps following before it unwinds.
SEAM_HYSTERESIS_DEG = 10.0


def lowest_sun_azimuth(latitude: float) -> float | None:
    """Azimuth (deg clockwise from north) of the sun's lowest point of the day where a
    midnight sun can pass it, else None.

    Beyond :data:`MIDNIGHT_SUN_LATITUDE_DEG` the sun's lower transit is due north (0) in the
    northern hemisphere and due south (180) in the southern one, on every day of the year.
    """
    if abs(latitude) < MIDNIGHT_SUN_LATITUDE_DEG:
        return None
    return 0.0 if latitude > 0 else 180.0


def _seam_window(lo: float, hi: float, seam: float) -> tuple[float, float] | None:
    """The turn ``[s - h, s + 360 + h]`` (``s`` congruent to ``seam``, the turn centred in
    ``[lo, hi]``, ``h`` the hysteresis) within which the axis follows, or None when no whole
    turn from seam to seam fits the travel."""
    start = seam + 360.0 * round(((lo + hi) / 2.0 - 180.0 - seam) / 360.0)
    if start < lo - 1e-9 or start + 360.0 > hi + 1e-9:
        return None
    return max(lo, start - SEAM_HYSTERESIS_DEG), min(hi, start + 360.0 + SEAM_HYSTERESIS_DEG)


def wrap_into_range(
    angle_deg: float, lo: float, hi: float, near: float | None = None, seam: float | None = None
) -> float:
    """Represent ``angle_deg`` (mod 360) inside [lo, hi]; clamp if no representative fits.

    When several representatives fit (a range wider than 360 deg), the one closest to
    ``near`` (the current axis angle) wins, so the axis never unwinds needlessly.  With a
    ``seam`` (deg; :func:`lowest_sun_azimuth`) and a travel that holds a whole turn from
    seam to seam, only representatives within that turn (plus the hysteresis) are taken,
    so the axis unwinds just past the seam and nowhere else.
    """
    base = angle_deg % 360.0
    candidates = [
        base + 360.0 * k for k in range(math.floor((lo - base) / 360.0), math.ceil((hi - base) / 360.0) + 1)
    ]
    inside = [c for c in candidates if lo - 1e-9 <= c <= hi + 1e-9]
    window = _seam_window(lo, hi, seam) if seam is not None and hi - lo > 360.0 else None
    if window is not None:
        # the turn spans 360 deg, so at least one representative lies within it
        inside = [c for c in inside if window[0] - 1e-9 <= c <= window[1] + 1e-9] or inside
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
    seam_deg: float | None = None,
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
    seam_deg : float, optional
        Azimuth of the sun's lowest point (:func:`lowest_sun_azimuth` of the site's
        latitude), where a travel wider than one turn unwinds.
    """
    az = wrap_into_range(sun_az_deg, *azimuth_limits, near=current_az_deg, seam=seam_deg)
    el = min(max(sun_el_deg, elevation_limits[0]), elevation_limits[1])
    return az, el
