"""How far each clear day's light is shifted in time from the computed sun: a clock check
that holds where the sun never sets.

The edges of the day's light (:func:`.plausibility.light_edge_rows`) tell a clock error
where the sun rises and sets steeply.  High in summer it grazes the horizon for hours, and
under a midnight sun there are no edges at all: at 65-70 deg N in June a record stamped a
whole hour (a daylight-saving mistake) or even two late went unseen.  A clear day's light
follows the sun's height all day, though, and its shape against time fixes the clock to
minutes wherever the sun's height changes over the day.

For each row, the GHI averaged over 5-min bins is fitted by ``a m(t - s)``, with ``m`` a
clear-sky shape (Haurwitz: ``cos z exp(-0.057 / cos z)``, the sun's height alone) and ``a``
free, for shifts ``s`` of up to :data:`MAX_SHIFT_H` either way; the best ``s`` is refined
by a parabola.  Only a day the shape fits within :data:`CLEAR_FIT_MAX` (RMS over the mean
of the daylight bins) counts: clouds, a shadow or dew leave a worse fit and no shift.
Errors in the shape that are symmetric about noon (turbidity, the sensor's cosine response)
scale or widen the fit and do not move it.
"""

from __future__ import annotations

import numpy as np

from .solar import cos_zenith_rows

__all__ = ["BIN_S", "CLEAR_FIT_MAX", "MAX_SHIFT_H", "clear_shift_rows", "haurwitz_shape"]

#: Bin width (s): finer samples are averaged to it, coarser ones kept as they are.
BIN_S = 300.0
#: Shifts searched, hours either way.
MAX_SHIFT_H = 3.0
#: A day is clear enough to time when the shape fits it within this share of its mean light.
CLEAR_FIT_MAX = 0.08
#: ... and its samples cover this share of the bins where the sun is computed up.
MIN_COVER = 0.8


def haurwitz_shape(cos_z: np.ndarray) -> np.ndarray:
    """Haurwitz's clear-sky GHI shape, ``cos z exp(-0.057 / cos z)`` (0 with the sun down)."""
    c = np.asarray(cos_z, np.float64)
    pos = np.maximum(c, 1e-6)
    return np.where(c > 0, pos * np.exp(-0.057 / pos), 0.0)


def _bins(ghi: np.ndarray, has: np.ndarray, step_s: int) -> tuple[np.ndarray, float]:
    """Mean GHI per bin (NaN where under half the bin holds samples), and the bin width (s)."""
    k = max(1, int(round(BIN_S / step_s)))
    rows, n = ghi.shape
    nb = n // k
    g = np.where(has, ghi, 0.0)[:, : nb * k].reshape(rows, nb, k).astype(np.float64)
    cnt = has[:, : nb * k].reshape(rows, nb, k).sum(axis=2)
    mean = g.sum(axis=2) / np.maximum(cnt, 1)
    return np.where(cnt * 2 >= k, mean, np.nan), float(k * step_s)


def clear_shift_rows(
    ghi: np.ndarray,
    has: np.ndarray,
    t0: np.ndarray,
    step_s: int,
    latitude: float,
    longitude: float,
    geometry: dict[str, np.ndarray],
) -> tuple[np.ndarray, np.ndarray]:
    """Time shift of each row's light against the computed sun, and how well it fits.

    Parameters
    ----------
    ghi, has : numpy.ndarray, shape (rows, n)
        GHI (W/m2) and the slots that hold a sample.
    t0 : numpy.ndarray, shape (rows,)
        POSIX time of slot 0, s.
    step_s : int
        Slot spacing, s.
    latitude, longitude : float
        Degrees, north and east positive.
    geometry : dict
        :func:`.solar.row_geometry` of the rows.

    Returns
    -------
    shift_h : numpy.ndarray, shape (rows,)
        Hours by which the light comes later than the computed sun (a clock or zone that
        stamps late reads positive); NaN for a row that is not clear, not covered, or
        whose best shift lies at the end of the search.
    fit : numpy.ndarray, shape (rows,)
        RMS misfit of the best shift over the mean light of the daylight bins (NaN
        without daylight).
    """
    g, width = _bins(ghi, has, step_s)
    rows, nb = g.shape
    t_bin = np.asarray(t0, float) + 0.5 * (width - step_s)  # each bin's centre
    shifts = np.arange(-MAX_SHIFT_H, MAX_SHIFT_H + 1e-9, 5.0 / 60.0)
    sse = np.full((rows, shifts.size), np.inf)
    ok = np.isfinite(g)
    gz = np.where(ok, g, 0.0)
    for j, s in enumerate(shifts):
        m = haurwitz_shape(cos_zenith_rows(t_bin - s * 3600.0, width, nb, latitude, longitude, geometry))
        m = np.where(ok, m, 0.0)
        mm = (m * m).sum(axis=1)
        a = np.where(mm > 0, (gz * m).sum(axis=1) / np.maximum(mm, 1e-12), 0.0)
        sse[:, j] = ((gz - a[:, None] * m) ** 2).sum(axis=1)
    best = np.argmin(sse, axis=1)
    inner = (best > 0) & (best < shifts.size - 1)
    b = np.clip(best, 1, shifts.size - 2)
    r = np.arange(rows)
    y0, y1, y2 = sse[r, b - 1], sse[r, b], sse[r, b + 1]
    den = y0 - 2.0 * y1 + y2
    frac = np.where(den > 0, 0.5 * (y0 - y2) / np.where(den > 0, den, 1.0), 0.0)
    shift_h = shifts[b] + np.clip(frac, -0.5, 0.5) * (shifts[1] - shifts[0])
    up = cos_zenith_rows(t_bin, width, nb, latitude, longitude, geometry) > 0
    day = up & ok
    n_day = day.sum(axis=1)
    mean_light = np.where(day, gz, 0.0).sum(axis=1) / np.maximum(n_day, 1)
    fit = np.sqrt(sse[r, best] / np.maximum(n_day, 1)) / np.maximum(mean_light, 1e-9)
    fit = np.where(n_day > 0, fit, np.nan)
    cover = n_day / np.maximum(up.sum(axis=1), 1)
    clear = inner & (fit <= CLEAR_FIT_MAX) & (cover >= MIN_COVER) & (mean_light > 0)
    return np.where(clear, shift_h, np.nan), fit
