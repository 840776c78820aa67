"""Sunshine duration: the WMO truth from DNI, and its pyranometric estimate from GHI alone.

WMO (CIMO Guide, Part I, ch. 8) defines sunshine as DNI >= 120 W/m2.  The relative
sunshine of a day (sunshine duration over day length) is an independent day-type truth
wherever a pyrheliometer exists.  The same guide accepts "pyranometric" sunshine recorders
that infer it from global irradiance; our estimate splits each minute's GHI into beam and
diffuse with the Erbs et al. (1982) decomposition (pvlib) and applies the same 120 W/m2
threshold to the inferred DNI.
"""

from __future__ import annotations

import numpy as np
import pvlib

#: WMO sunshine threshold on direct normal irradiance, W/m2.
WMO_SUNSHINE_DNI = 120.0

#: pvlib's default lower limit of cos(zenith) in the Erbs model.
ERBS_MIN_COS_ZENITH = 0.065


def sunshine_fraction(
    dni: np.ndarray,
    valid: np.ndarray,
    cos_zenith: np.ndarray,
    threshold: float = WMO_SUNSHINE_DNI,
    min_cos_zenith: float = 0.0,
) -> np.ndarray:
    """Relative sunshine per row: daylit slots with DNI >= threshold over daylit slots with data.

    Parameters
    ----------
    dni : numpy.ndarray, shape (rows, n)
        Direct normal irradiance, W/m2.
    valid : numpy.ndarray of bool, shape (rows, n)
        Slots with a DNI sample.
    cos_zenith : numpy.ndarray, shape (rows, n)
        Cosine of the zenith; daylight is cos_zenith > min_cos_zenith.
    threshold : float
        W/m2.
    min_cos_zenith : float
        0 (sun above the horizon) for the WMO relative sunshine.

    Returns
    -------
    numpy.ndarray, shape (rows,)
        Fraction in [0, 1]; NaN for a row with no daylit sample.
    """
    day = valid & (cos_zenith > min_cos_zenith)
    n = np.count_nonzero(day, axis=1)
    sun = np.count_nonzero(day & (dni >= threshold), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, sun / np.maximum(n, 1), np.nan)


def block_means(y: np.ndarray, valid: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Average consecutive groups of ``factor`` slots over valid slots; (means, any-valid)."""
    if factor == 1:
        return np.where(valid, y, np.nan), valid
    rows, n = y.shape
    shape = (rows, n // factor, factor)
    yy, vv = y[:, : shape[1] * factor].reshape(shape), valid[:, : shape[1] * factor].reshape(shape)
    s = np.sum(yy, axis=2, where=vv, dtype=np.float64)
    c = np.count_nonzero(vv, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(c > 0, s / np.maximum(c, 1), np.nan), c > 0


def pyranometric_dni(ghi_1min: np.ndarray, cos_zenith: np.ndarray, doy: np.ndarray) -> np.ndarray:
    """DNI inferred from 1-min GHI with the Erbs decomposition (pvlib), W/m2.

    Parameters
    ----------
    ghi_1min : numpy.ndarray, shape (rows, n)
        One-minute mean GHI, W/m2.
    cos_zenith : numpy.ndarray, shape (rows, n)
        Cosine of the zenith at each minute.
    doy : numpy.ndarray, shape (rows,)
        Day of year of each row.
    """
    zen = np.degrees(np.arccos(np.clip(cos_zenith, -1.0, 1.0)))
    doy2 = np.broadcast_to(np.asarray(doy, float)[:, None], ghi_1min.shape)
    out = pvlib.irradiance.erbs(np.maximum(np.nan_to_num(ghi_1min), 0.0).ravel(), zen.ravel(), doy2.ravel())
    return np.asarray(out["dni"], float).reshape(ghi_1min.shape)


def pyranometric_sunshine_fraction(
    ghi: np.ndarray,
    valid: np.ndarray,
    cos_zenith: np.ndarray,
    step_s: float,
    doy: np.ndarray,
    threshold: float = WMO_SUNSHINE_DNI,
) -> np.ndarray:
    """Relative sunshine per row estimated from GHI alone (Erbs DNI >= threshold).

    GHI is first averaged to one minute (the time base of the WMO definition and of the
    Erbs fit); slots coarser than a minute are used as they are.

    Parameters
    ----------
    ghi : numpy.ndarray, shape (rows, n)
        GHI on a regular grid of spacing ``step_s``, W/m2.
    valid : numpy.ndarray of bool
        Slots with a sample.
    cos_zenith : numpy.ndarray
        Cosine of the zenith per slot.
    step_s : float
        Grid spacing, s.
    doy : numpy.ndarray, shape (rows,)
        Day of year per row.

    Returns
    -------
    numpy.ndarray, shape (rows,)
    """
    factor = max(1, int(round(60.0 / step_s)))
    g1, v1 = block_means(np.asarray(ghi, np.float64), valid, factor)
    cz1, _ = block_means(np.asarray(cos_zenith, np.float64), np.ones_like(valid), factor)
    dni = pyranometric_dni(g1, cz1, doy)
    # Erbs is not defined below cos(zenith) = 0.065 (pvlib sets DNI to 0 there): count only
    # the minutes it can judge, so a clear day is not docked its first and last half hour
    return sunshine_fraction(dni, v1, cz1, threshold, min_cos_zenith=ERBS_MIN_COS_ZENITH)
