"""Variation-method fractal dimension of an irradiance signal (paper 002, after Dubuc 1989).

For a signal f sampled on [0, 1] (time and amplitude both normalised) the area covered at
scale dt is ``S(dt) = dt * sum_n |f(t_n + dt) - f(t_n)|`` over the 1/dt non-overlapping steps
``t_n = n dt``.  For a curve of dimension D, ``S(dt) ~ dt^(2 - D)``, so D is the slope of
``ln(S / dt^2)`` against ``ln(1 / dt)``: 1 for a smooth curve, 2 - H for fractional Brownian
motion with Hurst exponent H.

``dt * sum`` over 1/dt steps is the mean absolute increment at lag dt.  We estimate that
mean from every pair of samples ``dt`` apart (``increments="all-offsets"``, the average of
the non-overlapping sums over all k possible starting offsets: same expectation, far less
variance at the large scales where only ~20 non-overlapping steps fit in a day), or from
offset 0 only (``"non-overlapping"``, the paper read literally).  Using the mean rather than
``dt * count`` keeps the count exact when dt does not divide the span; summing every pair
without dividing (a common slip) shifts the slope by one.

Choice of the fit range (the paper's "optimal dt_max")
------------------------------------------------------
The fit uses the smallest m scales, m >= 3 and the largest at most half the record.  The
paper keeps the dt_max whose line has the smallest mean point-to-line distance; any line
through fewer points fits better, so that rule almost always returns m = 3 (seen on station
data, see FIELD-NOTES).  The default here, ``criterion="slope-se"``, keeps the m that
estimates the slope most precisely: the smallest standard error of the least-squares slope,
``sqrt(SSR / (m - 2) / Sxx)``.  More scales lengthen the lever arm (Sxx grows) and so win
while the log-log plot stays straight; a scale break (curvature) inflates SSR and stops the
growth.  Ties (an exactly straight plot) go to the larger m.  ``"mean-distance"`` (paper
literal) and ``"all"`` (every scale) are selectable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

#: The paper's scales, seconds (1, 2, 5, 7, 10, 14, 35 min).
PAPER_SCALES_S: tuple[float, ...] = (60.0, 120.0, 300.0, 420.0, 600.0, 840.0, 2100.0)

Criterion = Literal["slope-se", "mean-distance", "all"]
Increments = Literal["all-offsets", "non-overlapping"]


@dataclass(frozen=True)
class FractalResult:
    """Fractal dimension per row (day or window).

    Attributes
    ----------
    D : numpy.ndarray
        Fractal dimension (dimensionless, 1..2 for sensible signals); NaN when fewer than
        three scales are usable or the signal is constant.
    n_scales : numpy.ndarray
        Number of scales in the chosen fit (0 where D is NaN).
    dt_max_s : numpy.ndarray
        Largest scale used, s (NaN where D is NaN).
    slope_se : numpy.ndarray
        Standard error of the fitted slope (dimensionless).
    """

    D: np.ndarray
    n_scales: np.ndarray
    dt_max_s: np.ndarray
    slope_se: np.ndarray


def scale_lags(step_s: float, scales_s: tuple[float, ...] = PAPER_SCALES_S) -> np.ndarray:
    """Scales converted to integer sample lags (>= 1, unique, increasing)."""
    if step_s <= 0:
        raise ValueError("step_s must be positive")
    lags = np.unique(np.maximum(1, np.rint(np.asarray(scales_s, float) / step_s).astype(np.int64)))
    return lags


def mean_abs_increments(
    y: np.ndarray, valid: np.ndarray, lags: np.ndarray, increments: Increments = "all-offsets"
) -> np.ndarray:
    """Mean absolute increment of each row at each lag, over pairs whose ends are both valid.

    Parameters
    ----------
    y : numpy.ndarray, shape (rows, n)
        Signal on a regular grid (any unit; invalid slots may hold anything finite).
    valid : numpy.ndarray of bool, shape (rows, n)
        Slots that hold data and belong to the analysed window (daylight).
    lags : numpy.ndarray of int
        Lags in samples.
    increments : {"all-offsets", "non-overlapping"}
        Pair set, see the module docstring.

    Returns
    -------
    numpy.ndarray, shape (rows, len(lags))
        Mean |y[i + k] - y[i]|; NaN where no valid pair exists.
    """
    rows, n = y.shape
    out = np.full((rows, len(lags)), np.nan)
    if increments == "non-overlapping":
        first = np.where(valid.any(axis=1), valid.argmax(axis=1), 0)
    for j, k in enumerate(lags):
        if k >= n:
            continue
        if increments == "all-offsets":
            pair = valid[:, k:] & valid[:, :-k]
            d = np.abs(y[:, k:] - y[:, :-k])
            s = np.sum(d, axis=1, where=pair, dtype=np.float64)
            c = np.count_nonzero(pair, axis=1)
        elif increments == "non-overlapping":
            s = np.zeros(rows)
            c = np.zeros(rows, dtype=np.int64)
            # few rows in practice are misaligned; group rows by phase of their first slot
            for phase in np.unique(first % k):
                sel = (first % k) == phase
                idx = np.arange(phase, n, k)
                yy, vv = y[sel][:, idx], valid[sel][:, idx]
                pair = vv[:, 1:] & vv[:, :-1]
                s[sel] = np.sum(np.abs(np.diff(yy, axis=1)), axis=1, where=pair, dtype=np.float64)
                c[sel] = np.count_nonzero(pair, axis=1)
        else:
            raise ValueError(f"unknown increments {increments!r}")
        with np.errstate(invalid="ignore", divide="ignore"):
            out[:, j] = np.where(c > 0, s / np.maximum(c, 1), np.nan)
    return out


def fit_dimension(
    mean_incr: np.ndarray,
    lags: np.ndarray,
    span: np.ndarray,
    step_s: float,
    criterion: Criterion = "slope-se",
    min_points: int = 3,
) -> FractalResult:
    """Fit D = slope of ln(S / dt^2) against ln(1 / dt), choosing the scale range per row.

    Parameters
    ----------
    mean_incr : numpy.ndarray, shape (rows, n_lags)
        S at each lag (mean absolute increment, normalised amplitude), from
        :func:`mean_abs_increments`.
    lags : numpy.ndarray of int
        Lags in samples, increasing.
    span : numpy.ndarray, shape (rows,)
        Length of each row's analysed window in samples; time is normalised so that the
        window is [0, 1] (dt = lag / span).  Lags above span / 2 are not used.
    step_s : float
        Sample spacing, s (for ``dt_max_s``).
    criterion : {"slope-se", "mean-distance", "all"}
        Rule for the fit range, see the module docstring.
    min_points : int
        Fewest scales in a fit (>= 3 so that a residual exists).
    """
    rows, nl = mean_incr.shape
    span = np.asarray(span, float)[:, None]
    dt = lags[None, :] / np.maximum(span, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.log(1.0 / dt)
        yv = np.log(mean_incr / dt**2)
    usable = np.isfinite(yv) & (lags[None, :] <= span / 2.0) & (mean_incr > 0)
    # a fit over the first m scales needs all of them usable
    prefix_ok = np.cumprod(usable, axis=1).astype(bool)

    best_score = np.full(rows, np.inf)
    D = np.full(rows, np.nan)
    n_used = np.zeros(rows, dtype=np.int64)
    se_best = np.full(rows, np.nan)
    for m in range(max(min_points, 3), nl + 1):
        ok = prefix_ok[:, m - 1]
        if not ok.any():
            continue
        xs, ys = np.where(ok[:, None], x[:, :m], 0.0), np.where(ok[:, None], yv[:, :m], 0.0)
        xm, ym = xs.mean(axis=1, keepdims=True), ys.mean(axis=1, keepdims=True)
        sxx = np.sum((xs - xm) ** 2, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            b = np.sum((xs - xm) * (ys - ym), axis=1) / sxx
            resid = ys - ym - b[:, None] * (xs - xm)
            ssr = np.sum(resid**2, axis=1)
            se = np.sqrt(ssr / (m - 2) / sxx)
        if criterion == "slope-se":
            score = se
        elif criterion == "mean-distance":
            score = np.mean(np.abs(resid), axis=1) / np.sqrt(1.0 + b**2)
        elif criterion == "all":
            score = -np.full(rows, float(m))
        else:
            raise ValueError(f"unknown criterion {criterion!r}")
        # '<=' with a relative tolerance: exact ties (a straight plot) go to more scales
        better = ok & np.isfinite(b) & (score <= best_score * (1 + 1e-9) + 1e-12)
        best_score = np.where(better, score, best_score)
        D = np.where(better, b, D)
        n_used = np.where(better, m, n_used)
        se_best = np.where(better, se, se_best)
    dt_max = np.where(n_used > 0, lags[np.maximum(n_used - 1, 0)] * step_s, np.nan)
    return FractalResult(D=D, n_scales=n_used, dt_max_s=dt_max, slope_se=se_best)


def variation_dimension_rows(
    y: np.ndarray,
    valid: np.ndarray,
    step_s: float,
    *,
    scales_s: tuple[float, ...] = PAPER_SCALES_S,
    criterion: Criterion = "slope-se",
    increments: Increments = "all-offsets",
) -> FractalResult:
    """Fractal dimension of each row of a regular grid, over the row's valid slots.

    Parameters
    ----------
    y : numpy.ndarray, shape (rows, n)
        Irradiance (W/m2) or any signal on a regular grid of spacing ``step_s``.
    valid : numpy.ndarray of bool, shape (rows, n)
        Slots to analyse (daylight and not missing).  The window of a row runs from its
        first to its last valid slot; gaps inside it drop only the pairs they touch.
    step_s : float
        Grid spacing, s.
    scales_s, criterion, increments
        See :data:`PAPER_SCALES_S` and the module docstring.

    Returns
    -------
    FractalResult
    """
    y = np.asarray(y)
    valid = np.asarray(valid, bool)
    if y.ndim != 2 or y.shape != valid.shape:
        raise ValueError("y and valid must be 2-D arrays of the same shape")
    rows, n = y.shape
    has = valid.any(axis=1)
    first = np.where(has, valid.argmax(axis=1), 0)
    last = np.where(has, n - 1 - valid[:, ::-1].argmax(axis=1), -1)
    span = (last - first + 1).astype(float)
    # amplitude normalisation to [0, 1] per row (does not change the slope, keeps S readable)
    big = np.finfo(np.float32).max
    lo = np.min(np.where(valid, y, big), axis=1).astype(np.float64)
    hi = np.max(np.where(valid, y, -big), axis=1).astype(np.float64)
    rng = np.where(has & (hi > lo), hi - lo, np.nan)
    lags = scale_lags(step_s, scales_s)
    incr = mean_abs_increments(y, valid, lags, increments) / rng[:, None]
    return fit_dimension(incr, lags, span, step_s, criterion)


def variation_dimension(
    y: np.ndarray,
    step_s: float,
    *,
    scales_s: tuple[float, ...] = PAPER_SCALES_S,
    criterion: Criterion = "slope-se",
    increments: Increments = "all-offsets",
) -> float:
    """Fractal dimension of one regularly sampled signal (NaN samples are treated as gaps).

    Parameters
    ----------
    y : array_like, shape (n,)
        Signal, sampled every ``step_s`` seconds.
    step_s : float
        Sample spacing, s.  Scales shorter than one sample are rounded up to one sample.

    Returns
    -------
    float
        D, or NaN when fewer than three scales fit in half the record.
    """
    arr = np.asarray(y, dtype=np.float64)[None, :]
    valid = np.isfinite(arr)
    res = variation_dimension_rows(
        np.where(valid, arr, 0.0),
        valid,
        step_s,
        scales_s=scales_s,
        criterion=criterion,
        increments=increments,
    )
    return float(res.D[0])
