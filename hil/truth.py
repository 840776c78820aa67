"""Ground truth of the world: where the sun is (pvlib SPA) and where the panels point.

Written from first principles, independently of the controller's geometry, so that a
sign error in the controller shows up as pointing error instead of cancelling out.
Vectors are topocentric ENU (x East, y North, z Up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pvlib


def unit_from_azel(az_deg, el_deg) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)


def angle_deg(a, b) -> np.ndarray:
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    return np.degrees(np.arctan2(cross, np.sum(a * b, axis=-1)))


@dataclass(frozen=True)
class SunTruth:
    """Sun positions and clear-sky DNI at given times (arrays, degrees and W/m2)."""

    times: np.ndarray  # POSIX seconds
    azimuth: np.ndarray
    elevation: np.ndarray  # apparent (refracted)
    dni: np.ndarray

    @property
    def vectors(self) -> np.ndarray:
        return unit_from_azel(self.azimuth, self.elevation)


def sun_truth(
    times_s: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
    temperature_c: float = 12.0,
    linke_turbidity: float = 3.0,
) -> SunTruth:
    """pvlib SPA positions and Ineichen clear-sky DNI, vectorised over ``times_s``."""
    idx = pd.DatetimeIndex(pd.to_datetime(np.asarray(times_s, float), unit="s", utc=True))
    pressure = pvlib.atmosphere.alt2pres(altitude)
    sp = pvlib.solarposition.get_solarposition(
        idx,
        latitude,
        longitude,
        altitude=altitude,
        pressure=pressure,
        temperature=temperature_c,
        method="nrel_numpy",
    )
    am = pvlib.atmosphere.get_absolute_airmass(
        pvlib.atmosphere.get_relative_airmass(sp["apparent_zenith"]), pressure
    )
    dni_extra = pvlib.irradiance.get_extra_radiation(idx)
    cs = pvlib.clearsky.ineichen(
        sp["apparent_zenith"], am, linke_turbidity, altitude=altitude, dni_extra=dni_extra
    )
    dni = np.nan_to_num(cs["dni"].to_numpy(), nan=0.0)
    return SunTruth(
        np.asarray(times_s, float), sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy(), dni
    )


# -- panel orientation ---------------------------------------------------------------


def dual_axis_normal(az_axis_deg, el_axis_deg) -> np.ndarray:
    """Panel normal of an azimuth/elevation tracker whose axes read these angles."""
    return unit_from_azel(az_axis_deg, el_axis_deg)


def row_axis(axis_azimuth: float, axis_tilt: float) -> np.ndarray:
    """Unit vector along a single-axis row, pointing to ``axis_azimuth``.

    The row's end towards ``axis_azimuth`` is its low end: at zero rotation a tilted row
    faces ``axis_azimuth`` (an equator-facing tilt for 180 in the north), as in pvlib.
    """
    return unit_from_azel(axis_azimuth, -axis_tilt)


def row_normal(rotation_deg, axis_azimuth: float, axis_tilt: float) -> np.ndarray:
    """Panel normal of a row rotated by ``rotation_deg`` (right-handed about the axis).

    At zero rotation the normal is the upward vector perpendicular to the axis; for a
    north-south row a positive rotation turns it west (Rodrigues' formula).
    """
    a = row_axis(axis_azimuth, axis_tilt)
    up = np.array([0.0, 0.0, 1.0])
    n0 = up - np.dot(up, a) * a
    n0 /= np.linalg.norm(n0)
    th = np.radians(np.asarray(rotation_deg, float))[..., None]
    return n0 * np.cos(th) + np.cross(a, n0) * np.sin(th) + a * np.dot(a, n0) * (1 - np.cos(th))


def row_ideal_rotation(
    sun_vec: np.ndarray,
    axis_azimuth: float,
    axis_tilt: float,
    max_angle: float,
    gcr: float,
    cross_axis_tilt: float = 0.0,
    backtrack: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ideal row rotation for sun vectors: (rotation, true-tracking angle, backtracking?).

    True tracking puts the normal in the plane of the axis and the sun; backtracking
    (Anderson & Mikofski 2020) turns back just enough that the neighbouring row's shadow
    misses, given the ground coverage ratio and the cross-axis slope.
    """
    a = row_axis(axis_azimuth, axis_tilt)
    up = np.array([0.0, 0.0, 1.0])
    n0 = up - np.dot(up, a) * a
    n0 /= np.linalg.norm(n0)
    w = np.cross(a, n0)
    true = np.degrees(np.arctan2(sun_vec @ w, sun_vec @ n0))
    rot = true.copy()
    bt = np.zeros(true.shape, bool)
    if backtrack:
        temp = np.abs(np.cos(np.radians(true - cross_axis_tilt))) / (
            gcr * np.cos(np.radians(cross_axis_tilt))
        )
        bt = temp < 1
        corr = np.degrees(-np.sign(true) * np.arccos(np.minimum(temp, 1.0)))
        rot = np.where(bt, true + corr, true)
    rot = np.clip(rot, -max_angle, max_angle)
    return rot, true, bt


def row_pointing_error(
    rotation_deg, sun_vec: np.ndarray, axis_azimuth: float, axis_tilt: float
) -> np.ndarray:
    """Angle (deg) between the row's normal and the sun projected onto its rotation plane."""
    a = row_axis(axis_azimuth, axis_tilt)
    proj = sun_vec - (sun_vec @ a)[..., None] * a
    return angle_deg(row_normal(rotation_deg, axis_azimuth, axis_tilt), proj)


def poa_global_perez(
    normals: np.ndarray,
    times_s: np.ndarray,
    sun_azimuth: np.ndarray,
    sun_elevation: np.ndarray,
    ghi: np.ndarray,
    dni: np.ndarray,
    dhi: np.ndarray,
    albedo: float = 0.2,
) -> np.ndarray:
    """Global plane-of-array irradiance (W/m2) on panels with these normals, pvlib Perez."""
    tilt = np.degrees(np.arccos(np.clip(normals[:, 2], -1, 1)))
    azimuth = np.degrees(np.arctan2(normals[:, 0], normals[:, 1])) % 360.0
    idx = pd.DatetimeIndex(pd.to_datetime(np.asarray(times_s, float), unit="s", utc=True))
    zenith = 90.0 - np.asarray(sun_elevation, float)
    poa = pvlib.irradiance.get_total_irradiance(
        tilt,
        azimuth,
        zenith,
        sun_azimuth,
        dni,
        ghi,
        dhi,
        dni_extra=pvlib.irradiance.get_extra_radiation(idx).to_numpy(),
        airmass=pvlib.atmosphere.get_relative_airmass(zenith),
        albedo=albedo,
        model="perez",
    )
    return np.nan_to_num(np.asarray(poa["poa_global"], float))
