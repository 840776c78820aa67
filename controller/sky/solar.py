"""Cheap analytic solar geometry for day typing.

Per-sample SPA (:func:`controller.sun.source.solar_position`) costs about a minute for a
year of 2-s samples, far over the classifier's budget.  Day typing only needs the zenith
to about 0.3 deg (night mask, extraterrestrial irradiance) and the daily extraterrestrial
irradiation, so this module takes the declination, equation of time and Sun-Earth
distance factor once per row (a day, or a window of a few hours) from pvlib's Spencer
(1971) series and evaluates the zenith analytically per sample.  Refraction is ignored.
"""

from __future__ import annotations

import numpy as np
import pvlib

SECONDS_PER_DAY = 86400.0


def day_of_year(posix_s: np.ndarray) -> np.ndarray:
    """Fractional day of year (1 on 1 January 00:00 UTC) for POSIX seconds."""
    t = np.asarray(posix_s, dtype=float)
    year_start = t.astype("datetime64[s]").astype("datetime64[Y]").astype("datetime64[s]").astype(float)
    return 1.0 + (t - year_start) / SECONDS_PER_DAY


def row_geometry(t_mid_posix: np.ndarray) -> dict[str, np.ndarray]:
    """Declination, equation of time and extraterrestrial normal irradiance per row.

    Parameters
    ----------
    t_mid_posix : array_like
        One representative time per row (e.g. local solar noon), POSIX seconds.

    Returns
    -------
    dict
        ``declination`` (rad), ``eot_s`` (equation of time, s), ``e0`` (extraterrestrial
        normal irradiance, W/m2), ``doy`` (integer day of year).
    """
    doy = np.floor(day_of_year(t_mid_posix))
    return {
        "declination": np.asarray(pvlib.solarposition.declination_spencer71(doy), float),
        "eot_s": 60.0 * np.asarray(pvlib.solarposition.equation_of_time_spencer71(doy), float),
        "e0": np.asarray(pvlib.irradiance.get_extra_radiation(doy), float),
        "doy": doy,
    }


def cos_zenith_rows(
    t0_posix: np.ndarray,
    step_s: float,
    n_slots: int,
    latitude: float,
    longitude: float,
    geometry: dict[str, np.ndarray],
) -> np.ndarray:
    """Cosine of the solar zenith on a regular grid, one row per day or window.

    Parameters
    ----------
    t0_posix : array_like, shape (rows,)
        POSIX time (s) of slot 0 of each row.
    step_s : float
        Slot spacing, s.
    n_slots : int
        Slots per row.
    latitude, longitude : float
        Degrees, north and east positive.
    geometry : dict
        From :func:`row_geometry` for the same rows.

    Returns
    -------
    numpy.ndarray, shape (rows, n_slots)
        cos(zenith), float32 (2e-7 resolution is ample and halves memory traffic).
    """
    phi = np.radians(latitude)
    dec = geometry["declination"][:, None]
    # apparent solar time of slot 0, as a fraction of a day after solar midnight
    ast0 = (np.asarray(t0_posix, float) + longitude * 240.0 + geometry["eot_s"]) / SECONDS_PER_DAY
    frac0 = (ast0 - np.floor(ast0))[:, None]
    slot_frac = (np.arange(n_slots, dtype=np.float64) * (step_s / SECONDS_PER_DAY))[None, :]
    hour_angle = (2.0 * np.pi) * (frac0 + slot_frac) - np.pi
    a = (np.sin(phi) * np.sin(dec)).astype(np.float32)
    b = (np.cos(phi) * np.cos(dec)).astype(np.float32)
    return a + b * np.cos(hour_angle.astype(np.float32))


def sunset_hour_angle(latitude: float, declination: np.ndarray, elevation_deg: float = 0.0) -> np.ndarray:
    """Hour angle (rad) at which the sun crosses ``elevation_deg``; 0 in polar night, pi in polar day."""
    phi = np.radians(latitude)
    num = np.sin(np.radians(elevation_deg)) - np.sin(phi) * np.sin(declination)
    den = np.cos(phi) * np.cos(declination)
    return np.arccos(np.clip(num / den, -1.0, 1.0))


def daily_extraterrestrial_irradiation(
    latitude: float, declination: np.ndarray, e0: np.ndarray
) -> np.ndarray:
    """Extraterrestrial irradiation on a horizontal surface over a whole day, J/m2.

    H0 = (86400 / pi) * E0 * (cos(phi) cos(delta) sin(ws) + ws sin(phi) sin(delta)),
    with ws the sunset hour angle (Duffie & Beckman eq. 1.10.3).
    """
    phi = np.radians(latitude)
    ws = sunset_hour_angle(latitude, declination)
    return (
        (SECONDS_PER_DAY / np.pi)
        * e0
        * (np.cos(phi) * np.cos(declination) * np.sin(ws) + ws * np.sin(phi) * np.sin(declination))
    )
