"""The sun's orbit law, as the sky-only (``free``) Kalman mode uses it.

``sin(dec) = sin(eps) sin(lambda)``: the declination follows from the obliquity ``eps``
and the sun's ecliptic longitude ``lambda``.  The filter never reads ``lambda`` from an
ephemeris; it only needs how far ``lambda`` advances between two times, which is the
orbital rate (:func:`orbit_advance_deg`).  Angles in degrees, times in POSIX seconds (UTC).
"""

from __future__ import annotations

import numpy as np

#: Mean obliquity of the ecliptic (deg), IAU, J2000 (drifts 0.013 deg per century).
OBLIQUITY_DEG = 23.4393
#: Mean motion of the sun in ecliptic longitude, deg/day (tropical year).
MEAN_MOTION_DEG_PER_DAY = 0.98564736
#: Seconds per day.
DAY_S = 86400.0
#: Angular frequency of the seasons, rad/day (tropical year 365.2422 days).
OMEGA_YEAR = 2.0 * np.pi / 365.2422
#: Orbital-rate models accepted by :func:`orbit_advance_deg`.
ORBIT_RATES = ("kepler", "mean")


def equation_of_centre_deg(t) -> np.ndarray:
    """Kepler's equation of centre (deg) at POSIX ``t`` (s).

    ``C(M) = 1.914602 sin M + 0.019993 sin 2M + 0.000289 sin 3M`` with the mean anomaly
    ``M = 357.52911 + 0.98560028 d`` (deg; ``d`` in days from J2000): the true minus the
    mean anomaly of an orbit with eccentricity 0.0167, perihelion in early January.
    """
    d = (np.asarray(t, dtype=float) / DAY_S) - 10957.5
    m = np.radians(357.52911 + 0.98560028 * d)
    return 1.914602 * np.sin(m) + 0.019993 * np.sin(2 * m) + 0.000289 * np.sin(3 * m)


def orbit_advance_deg(t0, t1, rate: str = "kepler"):
    """Advance of the sun's ecliptic longitude (deg) from POSIX ``t0`` to ``t1`` (s).

    Parameters
    ----------
    t0, t1 : float or array_like
        POSIX seconds (UTC); ``t1 < t0`` gives a negative advance.
    rate : {"kepler", "mean"}
        ``"mean"``: the mean motion only (0.98564736 deg/day).  ``"kepler"``: plus the
        change of Kepler's equation of centre (:func:`equation_of_centre_deg`), i.e. the
        orbital rate of a Keplerian orbit with eccentricity 0.0167 (0.953 deg/day in July,
        1.019 in January).

    Returns
    -------
    float or ndarray
        Only differences of longitude, deg: the longitude itself (the date in the tropical
        year, hence the declination) is the filter's state, learnt from the sky.
    """
    d0 = (np.asarray(t0, dtype=float) / DAY_S) - 10957.5
    d1 = (np.asarray(t1, dtype=float) / DAY_S) - 10957.5
    adv = MEAN_MOTION_DEG_PER_DAY * (d1 - d0)
    if rate == "mean":
        return adv
    if rate != "kepler":
        raise ValueError(f"orbit_rate must be 'kepler' or 'mean', got {rate!r}")
    return adv + equation_of_centre_deg(t1) - equation_of_centre_deg(t0)


def orbit_rotation(t0: float, t1: float, rate: str = "kepler") -> tuple[float, float]:
    """``(cos, sin)`` of the advance of ``lambda`` from ``t0`` to ``t1``.

    The ``free`` state's ``(u, v) = sin(eps) (sin lambda, cos lambda)`` becomes
    ``(c u + s v, -s u + c v)``: a rotation, so it keeps the vector's length (the
    obliquity) and propagates the covariance exactly.
    """
    th = np.radians(orbit_advance_deg(t0, t1, rate))
    return float(np.cos(th)), float(np.sin(th))
