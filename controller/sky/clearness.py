"""Clearness index K_T = H / H0 of a day or a window."""

from __future__ import annotations

import numpy as np


def clearness_index_rows(
    ghi: np.ndarray,
    valid: np.ndarray,
    cos_zenith: np.ndarray,
    step_s: float,
    e0: np.ndarray,
    h0: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Clearness index per row, with gaps filled at the row's own clearness.

    Parameters
    ----------
    ghi : numpy.ndarray, shape (rows, n)
        Global horizontal irradiance, W/m2 (negatives, i.e. thermal offsets, count as 0).
    valid : numpy.ndarray of bool, shape (rows, n)
        Slots that hold a sample.
    cos_zenith : numpy.ndarray, shape (rows, n)
        Cosine of the solar zenith per slot.
    step_s : float
        Slot length, s.
    e0 : numpy.ndarray, shape (rows,)
        Extraterrestrial normal irradiance, W/m2.
    h0 : numpy.ndarray, shape (rows,), optional
        Extraterrestrial horizontal irradiation of the row, J/m2 (analytic, for whole days).
        When omitted it is the sum of E0 cos(zenith) over the row's daylit slots.

    Returns
    -------
    dict
        ``K_T`` (dimensionless), ``H`` (ground irradiation over the row, J/m2, missing daylit
        slots filled in proportion to their extraterrestrial irradiance), ``H0`` (J/m2),
        ``coverage`` (fraction of the row's extraterrestrial irradiation that had data).
    """
    up = cos_zenith > 0
    g0 = np.where(up, cos_zenith, 0.0)
    g0_all = np.sum(g0, axis=1, dtype=np.float64)
    g0_valid = np.sum(g0, axis=1, where=valid, dtype=np.float64)
    h_meas = step_s * np.sum(np.maximum(ghi, 0.0), axis=1, where=valid & up, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        coverage = g0_valid / g0_all
        H = h_meas / coverage
        H0 = np.asarray(h0, float) if h0 is not None else step_s * e0 * g0_all
        kt = H / H0
    kt = np.where(g0_all > 0, kt, np.nan)
    return {"K_T": np.asarray(kt), "H": np.asarray(H), "H0": np.asarray(H0), "coverage": np.asarray(coverage)}
