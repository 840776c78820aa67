"""The paper's noon formulas: declination, latitude and longitude from solar noon.

At upper culmination the sun's zenith distance is ``|lat - dec|``.  When it culminates in
the south (``lat > dec``, usual in the northern hemisphere) ``el = 90 - lat + dec``; in the
north (``lat < dec``, usual in the southern hemisphere) ``el = 90 + lat - dec``.
Longitude follows from the UTC time of noon and the equation of time:
``lon = -15 (noon_utc_hours - 12) - EoT / 4`` (deg, east-positive; EoT in minutes).
"""

from __future__ import annotations

import numpy as np

from .ephemeris import equation_of_time_min, geocentric_sun, wrap180


def declination_from_noon(noon_el_deg, lat_deg, culmination: str = "south"):
    """Declination (deg) from noon elevation and latitude (paper: dec = el + lat - 90)."""
    if culmination == "south":
        return np.asarray(noon_el_deg) + lat_deg - 90.0
    if culmination == "north":
        return 90.0 + lat_deg - np.asarray(noon_el_deg)
    raise ValueError("culmination must be 'south' or 'north'")


def latitude_from_noon(noon_el_deg, dec_deg, culmination: str = "south"):
    """Latitude (deg) from noon elevation and the known declination."""
    if culmination == "south":
        return 90.0 - np.asarray(noon_el_deg) + dec_deg
    if culmination == "north":
        return np.asarray(noon_el_deg) - 90.0 + dec_deg
    raise ValueError("culmination must be 'south' or 'north'")


def longitude_from_noon(noon_utc):
    """East-positive longitude (deg) from the observed noon (POSIX s) and SPA's EoT."""
    noon_utc = np.asarray(noon_utc, dtype=float)
    utc_h = (noon_utc % 86400.0) / 3600.0
    return wrap180(-15.0 * (utc_h - 12.0) - equation_of_time_min(noon_utc) / 4.0)


def culmination_side(az_at_noon_deg) -> str:
    """``"south"`` when the noon azimuth (ENU, deg) is nearer 180 than 0, else ``"north"``."""
    return "south" if abs(float(wrap180(az_at_noon_deg - 180.0))) < 90.0 else "north"


def ephemeris_declination(t):
    """SPA geocentric declination (deg) at POSIX ``t``."""
    return geocentric_sun(t).dec_deg
