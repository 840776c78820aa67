"""Simpler day-type rules to measure the paper's rule and the default against.

* K_T alone, with fixed a-priori thresholds (clear >= 0.65, overcast < 0.35; the usual
  daily-clearness bands, e.g. Iqbal 1983), never tuned on the benchmark.
* The daily clear fraction from pvlib's ``detect_clearsky`` (Reno & Hansen 2016) applied to
  one-minute GHI against the Ineichen clear sky with the site's monthly Linke turbidity.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pvlib

from .sunshine import block_means


def classify_by_kt(k_t: np.ndarray, clear: float = 0.65, overcast: float = 0.35) -> np.ndarray:
    """Day class from K_T alone: 1 (I) if K_T >= clear, 3 (III) if K_T < overcast, else 2; 0 if NaN."""
    k = np.asarray(k_t, float)
    out = np.where(k >= clear, 1, np.where(k < overcast, 3, 2))
    return np.where(np.isfinite(k), out, 0)


def classify_by_fraction(fraction: np.ndarray, clear: float = 0.8, overcast: float = 0.2) -> np.ndarray:
    """Day class from a fraction of daylight (sunshine or clear minutes): I >= clear, III <= overcast."""
    f = np.asarray(fraction, float)
    out = np.where(f >= clear, 1, np.where(f <= overcast, 3, 2))
    return np.where(np.isfinite(f), out, 0)


def ineichen_rows(
    cos_zenith: np.ndarray,
    e0: np.ndarray,
    month: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
) -> np.ndarray:
    """Ineichen clear-sky GHI (W/m2) on a grid of rows, with the monthly Linke turbidity."""
    zen = np.degrees(np.arccos(np.clip(cos_zenith, -1.0, 1.0)))
    # one lookup per row: the climatology is monthly, interpolated to mid-month by pvlib
    idx = pd.DatetimeIndex(
        pd.to_datetime({"year": 2001, "month": np.asarray(month, int), "day": 15}), tz="UTC"
    )
    tl = np.asarray(
        pvlib.clearsky.lookup_linke_turbidity(idx, latitude, longitude, interp_turbidity=False), float
    )
    am_rel = pvlib.atmosphere.get_relative_airmass(zen)
    am_abs = pvlib.atmosphere.get_absolute_airmass(am_rel, pvlib.atmosphere.alt2pres(altitude))
    with np.errstate(divide="ignore", invalid="ignore"):  # night: airmass is NaN
        cs = pvlib.clearsky.ineichen(
            zen,
            am_abs,
            np.broadcast_to(tl[:, None], zen.shape),
            altitude=altitude,
            dni_extra=np.broadcast_to(np.asarray(e0, float)[:, None], zen.shape),
        )
    return np.nan_to_num(np.asarray(cs["ghi"], float))


def detect_clearsky_fraction(
    ghi: np.ndarray,
    valid: np.ndarray,
    cos_zenith: np.ndarray,
    step_s: float,
    e0: np.ndarray,
    month: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float = 0.0,
    min_elevation_deg: float = 5.0,
) -> np.ndarray:
    """Fraction of daylit minutes that pvlib ``detect_clearsky`` flags as clear, per row.

    GHI is averaged to one minute, the sampling ``detect_clearsky`` was designed for (its
    default 10-min window and limits).  Minutes with the sun below ``min_elevation_deg``
    are left out: the method's limits are not meant for the horizon.
    """
    factor = max(1, int(round(60.0 / step_s)))
    g1, v1 = block_means(np.asarray(ghi, np.float64), valid, factor)
    cz1, _ = block_means(np.asarray(cos_zenith, np.float64), np.ones_like(valid), factor)
    cs = ineichen_rows(cz1, e0, month, latitude, longitude, altitude)
    rows, n = g1.shape
    minutes = max(1, int(round(step_s * factor / 60.0)))
    # the rows are concatenated on a synthetic regular index: only its spacing is used,
    # and nights separate the days so windows never straddle two rows with sun
    times = pd.date_range("2001-01-01", periods=rows * n, freq=f"{minutes}min", tz="UTC")
    with warnings.catch_warnings():  # pvlib 0.16 uses a pandas API that pandas deprecates
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", FutureWarning)
        clear = pvlib.clearsky.detect_clearsky(
            pd.Series(np.nan_to_num(g1.ravel()), index=times), pd.Series(cs.ravel(), index=times)
        )
    clear = np.asarray(clear, bool).reshape(rows, n)
    day = v1 & (cz1 > np.sin(np.radians(min_elevation_deg)))
    cnt = np.count_nonzero(day, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, np.count_nonzero(clear & day, axis=1) / np.maximum(cnt, 1), np.nan)
