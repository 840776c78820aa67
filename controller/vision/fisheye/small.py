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
    if n == 4:  # the blend's step, some twenty times a frame: unrolled
        return _solve_spd4(M, g, tiny)
    if n == 5:  # the cone's harmonics, some ten times a frame: unrolled
        return _solve_spd5(M, g, tiny)
    return _solve_spd_any(M, g, tiny)


def _solve_spd_any(M: list[list[float]], g: list[float], tiny: float) -> list[float] | None:
    """:func:`solve_spd` of any size, by loops."""
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


def _solve_spd4(M: list[list[float]], g: list[float], tiny: float) -> list[float] | None:
    """:func:`solve_spd` of a 4 x 4 system: the 5 x 5 one bordered by an identity row and
    column (the border's terms are exact zeros: the same values as unrolled for 4)."""
    x = _solve_spd5([[*M[0], 0.0], [*M[1], 0.0], [*M[2], 0.0], [*M[3], 0.0], _BORDER], [*g, 0.0], tiny)
    return None if x is None else x[:4]


_BORDER = [0.0, 0.0, 0.0, 0.0, 1.0]


def _solve_spd5(M: list[list[float]], g: list[float], tiny: float) -> list[float] | None:
    """:func:`solve_spd` of a 5 x 5 system, the same operations unrolled."""
    (m00, m01, m02, m03, m04), (_, m11, m12, m13, m14), (_, _, m22, m23, m24) = M[0], M[1], M[2]
    m33, m34, m44 = M[3][3], M[3][4], M[4][4]
    if not m00 > tiny * m00:
        return None
    l00 = math.sqrt(m00)
    l10, l20, l30, l40 = m01 / l00, m02 / l00, m03 / l00, m04 / l00
    d = m11 - l10 * l10
    if not d > tiny * m11:
        return None
    l11 = math.sqrt(d)
    l21, l31, l41 = (m12 - l20 * l10) / l11, (m13 - l30 * l10) / l11, (m14 - l40 * l10) / l11
    d = m22 - l20 * l20 - l21 * l21
    if not d > tiny * m22:
        return None
    l22 = math.sqrt(d)
    l32 = (m23 - l30 * l20 - l31 * l21) / l22
    l42 = (m24 - l40 * l20 - l41 * l21) / l22
    d = m33 - l30 * l30 - l31 * l31 - l32 * l32
    if not d > tiny * m33:
        return None
    l33 = math.sqrt(d)
    l43 = (m34 - l40 * l30 - l41 * l31 - l42 * l32) / l33
    d = m44 - l40 * l40 - l41 * l41 - l42 * l42 - l43 * l43
    if not d > tiny * m44:
        return None
    l44 = math.sqrt(d)
    y0 = g[0] / l00
    y1 = (g[1] - l10 * y0) / l11
    y2 = (g[2] - l20 * y0 - l21 * y1) / l22
    y3 = (g[3] - l30 * y0 - l31 * y1 - l32 * y2) / l33
    y4 = (g[4] - l40 * y0 - l41 * y1 - l42 * y2 - l43 * y3) / l44
    x4 = y4 / l44
    x3 = (y3 - l43 * x4) / l33
    x2 = (y2 - l32 * x3 - l42 * x4) / l22
    x1 = (y1 - l21 * x2 - l31 * x3 - l41 * x4) / l11
    return [(y0 - l10 * x1 - l20 * x2 - l30 * x3 - l40 * x4) / l00, x1, x2, x3, x4]


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


def clip_unit(x: np.ndarray) -> np.ndarray:
    """``np.clip(x, -1.0, 1.0)`` (a cosine's rounding kept in range) without its wrapper."""
    return np.minimum(np.maximum(x, -1.0), 1.0)
