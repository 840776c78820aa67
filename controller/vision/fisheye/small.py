"""Statistics and algebra of the few dozen values the rim's fits handle at a time.

numpy's general functions spend more on dispatch than on a rim's 30-100 values: a frame
calls a median some thirty times, and at 200 frames/s each microsecond is 0.02 % of the
budget.  The medians give numpy's results, value for value, on that hot path; the small
solve replaces ``np.linalg.lstsq`` on a fit's normal equations (the same step to rounding).
"""

from __future__ import annotations

import math

import numpy as np


def median(x: np.ndarray) -> float:
    """``float(np.median(x))`` of a 1-D array: the middle value, or the mean of the two
    middle values; NaN when ``x`` is empty or holds a NaN (as numpy)."""
    n = x.size
    if n == 0:
        return math.nan
    h = n // 2
    if n % 2:
        p = np.partition(x, (h, n - 1))  # the last slot: the largest, NaN if there is one
        m = p[h]
    else:
        p = np.partition(x, (h - 1, h, n - 1))
        m = (p[h - 1] + p[h]) / 2
    if np.isnan(p[n - 1]):
        return math.nan
    return float(m)


def median_rows(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=1)`` of a 2-D array without NaN (each row's middle value, or the
    mean of its two middle values)."""
    n = x.shape[1]
    h = n // 2
    if n % 2:
        return np.partition(x, h, axis=1)[:, h]
    p = np.partition(x, (h - 1, h), axis=1)
    return (p[:, h - 1] + p[:, h]) / 2


def median_kept(x: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Each row's median over its ``keep`` entries (``x``, ``keep``: 2-D, every row keeping
    at least one): ``np.median(x[i][keep[i]])`` row by row, in one sort."""
    s = np.sort(np.where(keep, x, np.inf), axis=1)
    n = keep.sum(axis=1)
    r = np.arange(x.shape[0])
    hi = s[r, n // 2]
    lo = s[r, np.maximum(n - 1, 0) // 2]
    return np.where(n % 2 == 1, hi, (lo + hi) / 2)


def solve_spd(M: list[list[float]], g: list[float], tiny: float = 1e-10) -> list[float] | None:
    """Solve ``M x = g`` for a small symmetric positive definite ``M`` (nested lists) by
    Cholesky, in floats; None when a pivot falls under ``tiny`` times its diagonal entry
    (columns this close to dependent lose their precision in normal equations: the caller
    falls back to ``np.linalg.lstsq`` on the design matrix)."""
    n = len(g)
    L = [row[:] for row in M]
    for j in range(n):
        Lj = L[j]
        d = Lj[j]
        for k in range(j):
            d -= Lj[k] * Lj[k]
        if not d > tiny * M[j][j]:
            return None
        d = math.sqrt(d)
        Lj[j] = d
        for i in range(j + 1, n):
            Li = L[i]
            t = Li[j]
            for k in range(j):
                t -= Li[k] * Lj[k]
            Li[j] = t / d
    y = list(g)
    for i in range(n):
        Li = L[i]
        t = y[i]
        for k in range(i):
            t -= Li[k] * y[k]
        y[i] = t / Li[i]
    for i in range(n - 1, -1, -1):
        t = y[i]
        for k in range(i + 1, n):
            t -= L[k][i] * y[k]
        y[i] = t / L[i][i]
    return y


def gradient(f: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.gradient(f, x)`` of 1-D float arrays (at least two values), value for value and
    in ``f``'s precision: second-order differences inside, first-order at the ends, numpy's
    formulas for even or uneven steps, without its general machinery (a third of the cost
    on a ring's profile)."""
    dx = np.diff(x)
    out = np.empty_like(f)  # in f's precision, as numpy
    if (dx == dx[0]).all():
        h = dx[0]
        out[1:-1] = (f[2:] - f[:-2]) / (2.0 * h)
        out[0] = (f[1] - f[0]) / h
        out[-1] = (f[-1] - f[-2]) / h
        return out
    dx1, dx2 = dx[:-1], dx[1:]
    a = -(dx2) / (dx1 * (dx1 + dx2))
    b = (dx2 - dx1) / (dx1 * dx2)
    c = dx1 / (dx2 * (dx1 + dx2))
    out[1:-1] = a * f[:-2] + b * f[1:-1] + c * f[2:]
    out[0] = (f[1] - f[0]) / dx[0]
    out[-1] = (f[-1] - f[-2]) / dx[-1]
    return out
