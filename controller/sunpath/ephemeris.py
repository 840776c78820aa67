"""Geocentric sun ephemeris and the spherical-astronomy model of the sun's apparent path.

The site-independent part of the sun's position (apparent sidereal time at Greenwich,
right ascension and declination) comes from pvlib's SPA implementation, so the sun-path
filters need no site to evaluate it.  The site-dependent part is the textbook conversion
from hour angle and declination to azimuth and elevation, plus SPA's refraction formula.

Conventions: degrees; azimuth clockwise from north (0 N, 90 E); longitude east-positive;
hour angle negative in the morning, zero at transit; times are POSIX seconds (UTC).
Topocentric parallax (at most 0.0024 deg) is neglected.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pvlib

#: SPA's default apparent sun-set refraction allowance (deg), used only by its switch.
_ATMOS_REFRACT = 0.5667
#: True elevation (deg) below which SPA applies no refraction: its sun-set switch, where
#: the apparent elevation steps by 0.616 deg (from -0.833 to -0.217 at 1013 hPa, 12 C).
REFRACTION_SWITCH_DEG = -(0.26667 + _ATMOS_REFRACT)


@dataclass(frozen=True)
class GeocentricSun:
    """Site-independent sun ephemeris at given times (arrays, degrees).

    Attributes
    ----------
    sidereal_deg : ndarray
        Apparent Greenwich sidereal time.
    ra_deg : ndarray
        Geocentric right ascension.
    dec_deg : ndarray
        Geocentric declination, north-positive.
    """

    sidereal_deg: np.ndarray
    ra_deg: np.ndarray
    dec_deg: np.ndarray

    def hour_angle_deg(self, lon_deg) -> np.ndarray:
        """Local hour angle (deg, in [-180, 180)) at east-positive longitude ``lon_deg``."""
        return wrap180(self.sidereal_deg + lon_deg - self.ra_deg)


def wrap180(a):
    """Wrap angles (deg) to [-180, 180)."""
    return (np.asarray(a, dtype=float) + 180.0) % 360.0 - 180.0


def geocentric_sun(t) -> GeocentricSun:
    """SPA sidereal time, right ascension and declination at POSIX times ``t`` (s, UTC)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    dt = _utc(t)
    delta_t = pvlib.spa.calculate_deltat(dt.year.to_numpy(), dt.month.to_numpy())
    v, alpha, delta = pvlib.spa.solar_position_numpy(
        t, 0.0, 0.0, 0.0, 1013.25, 12.0, np.asarray(delta_t, dtype=float), _ATMOS_REFRACT, 1, sst=True
    )
    return GeocentricSun(np.asarray(v, float), np.asarray(alpha, float), np.asarray(delta, float))


def _utc(t):
    import pandas as pd

    return pd.DatetimeIndex(pd.to_datetime(t, unit="s", utc=True))


def equation_of_time_min(t) -> np.ndarray:
    """Equation of time (minutes, apparent minus mean solar time) from SPA at POSIX ``t``.

    Defined so that ``H = 15 (UTC hours - 12) + lon + EoT / 4`` (deg).
    """
    t = np.atleast_1d(np.asarray(t, dtype=float))
    g = geocentric_sun(t)
    utc_h = (t % 86400.0) / 3600.0
    return 4.0 * wrap180(g.sidereal_deg - g.ra_deg - 15.0 * (utc_h - 12.0))


def transit_time(t_guess, lon_deg) -> np.ndarray:
    """Time (POSIX s) of the sun's upper transit (hour angle 0) nearest ``t_guess``.

    Newton iterations on the SPA hour angle; converges to well under a second.
    """
    t = np.atleast_1d(np.asarray(t_guess, dtype=float)).copy()
    lon = np.broadcast_to(np.asarray(lon_deg, dtype=float), t.shape)
    for _ in range(4):
        h = geocentric_sun(t).hour_angle_deg(lon)
        t -= h / (360.0 / 86400.0)  # the sun's hour angle advances ~360 deg per solar day
    return t


def refraction_deg(el0_deg, pressure_hpa: float = 1013.25, temp_c: float = 12.0, continuous: bool = False):
    """SPA atmospheric refraction (deg) for true (airless) elevation ``el0_deg``.

    SPA applies none below :data:`REFRACTION_SWITCH_DEG`, a step of 0.616 deg there.
    ``continuous=True`` holds the value at the switch below it instead: not SPA's value
    there, but a continuous function with SPA's slope everywhere except the step itself,
    for numeric derivatives (a difference across the step is 0.616 deg over the step
    size: a near-infinite slope, and a covariance collapsed by orders of magnitude).
    """
    el0 = np.asarray(el0_deg, dtype=float)
    if continuous:
        el0 = np.maximum(el0, REFRACTION_SWITCH_DEG)
    return pvlib.spa.atmospheric_refraction_correction(pressure_hpa, temp_c, el0, _ATMOS_REFRACT)


def azel_from_hour_angle(
    hour_angle_deg,
    dec_deg,
    lat_deg,
    refraction_scale=1.0,
    pressure_hpa: float = 1013.25,
    temp_c: float = 12.0,
    continuous_refraction: bool = False,
):
    """Apparent azimuth and elevation (deg) of the sun from hour angle and declination.

    ``el0 = asin(sin(lat) sin(dec) + cos(lat) cos(dec) cos(H))``;
    ``az = atan2(sin H, cos H sin(lat) - tan(dec) cos(lat)) + 180`` (clockwise from north);
    refraction (SPA formula times ``refraction_scale``) is added to the elevation.
    ``continuous_refraction``: without SPA's step at the horizon (:func:`refraction_deg`),
    for the numeric Jacobians of the geometry only; the model itself is SPA's.

    Returns
    -------
    az_deg, el_deg : ndarray
    """
    h = np.radians(hour_angle_deg)
    d = np.radians(dec_deg)
    p = np.radians(lat_deg)
    s = np.sin(p) * np.sin(d) + np.cos(p) * np.cos(d) * np.cos(h)
    el0 = np.degrees(np.arcsin(np.clip(s, -1.0, 1.0)))
    az = (np.degrees(np.arctan2(np.sin(h), np.cos(h) * np.sin(p) - np.tan(d) * np.cos(p))) + 180.0) % 360.0
    el = el0 + refraction_scale * refraction_deg(el0, pressure_hpa, temp_c, continuous_refraction)
    return az, el
