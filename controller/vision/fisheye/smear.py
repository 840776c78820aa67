"""A frame-transfer CCD's column smear: estimated far from the glare, taken off the rim's samples.

While a frame-transfer CCD shifts its charge to the store, every pixel of a column passes
under the light that falls on that column, so each column gains one level along its whole
length, in proportion to the light the column crosses: faint, except in the columns that
cross the sun's glare (docs/fisheye.md, step 7).  The level is the same in every row, so it
can be read where nothing else is: in rows well above and below the glare, where each row
is detrended across the columns by a quadratic fitted beside the glare's columns, and best
of all outside the image circle, where it lies alone on black.  The glare's rim sits in
those same columns, and a level added to them raises the rim's top and bottom rays by the
level over the rim's slope: the third renderer's smear (10 grey levels at 640 x 480) moved
the fix 0.06-0.08 deg along the sun's vertical, one way in the morning, the other in the
afternoon (docs/fisheye-rounds.md, a seventeenth round).

The estimate is kept only when it is a smear: the rows above and the rows below the glare
both see it, at the same level within noise, and it stands clear of their noise.  Anything
else (no smear, a cloud in some rows, a ground's texture) is no smear, and nothing is
taken off.  A saturated pixel is left as it is: its light, smear included, is unknown.
The removal is on with a camera's sky calibration (``GlareOptions.column_smear``, bundle
``[orientation] sky_calibration``): alone, on the third renderer, it exposed the aureole's
bias that the smear had partly offset (docs/fisheye-rounds.md, a twenty-first round).  It
is on with the site too (:func:`.frames.with_sky_scale`): the sky's rings that may then
place the sun (:mod:`.rings`) read the smear as the sky's light.
"""

from __future__ import annotations

import math

import numpy as np

from .blobs import Blob
from .glare import GlareFit, GlareOptions, fit_glare
from .lens import FisheyeLens
from .radiometry import Radiometry
from .small import median, median_rows

MAX_ROWS = 80  # rows read each side (spread over it)
MIN_ROWS = 3  # rows each side (above, below) that must see the smear
MIN_LEVEL = 0.5  # grey levels: a smear fainter than this is not taken off
SIGNIFICANCE = 5.0  # ... nor one within this many of its standard errors of nothing
AGREEMENT = 0.25  # the levels above and below agree within this share (or MIN_LEVEL)


def column_smear(grey: np.ndarray, blobs: list[Blob], peak: float) -> np.ndarray | None:
    """The smear's level in each column of ``grey`` (grey levels, float32, shape (W,)), zero
    outside the columns of the saturated ``blobs`` and where none is seen; None when no
    column shows one.

    For each blob: rows more than four half-sizes from its centre, each detrended by a
    quadratic fitted on ``max(6, half-size)`` columns each side of the blob's, beyond a
    margin of half its half-size.  Rows whose reference columns the quadratic does not fit
    (an edge of the image circle, a horizon, a cloud: a residual over three times the
    median row's, or 2 grey levels) or that hold a saturated pixel are dropped.  The rows
    left form two groups read apart, those above the glare and those below it, or, when
    only one side has rows, its nearer and its further half: a smear is the same all along
    its column, so each of the blob's columns counts where both groups see it at the same
    level (within a quarter, or ``MIN_LEVEL``), clear of their noise (``SIGNIFICANCE``
    standard errors of each group's median, and ``MIN_LEVEL``).
    """
    H, W = grey.shape
    out = np.zeros(W, np.float32)
    for blob in blobs:
        bx, by, bw, bh = blob.bbox
        half = 0.5 * max(bw, bh)
        m = max(2, int(round(0.5 * half)))
        nr = max(6, int(round(half)))
        s0, s1 = bx - m - nr, bx + bw + m + nr
        if s0 < 0 or s1 > W:
            continue
        yc, e = by + 0.5 * bh, 4.0 * half
        up, down = np.arange(0, max(int(yc - e), 0)), np.arange(min(int(math.ceil(yc + e)), H), H)
        # at most MAX_ROWS a side, spread over it: the medians need no more, and it is cheap
        rows = np.r_[up[:: -(-up.size // MAX_ROWS) or 1], down[:: -(-down.size // MAX_ROWS) or 1]]
        if rows.size < 2 * MIN_ROWS:
            continue
        x = (np.arange(s0, s1) - 0.5 * (s0 + s1 - 1)) / (0.5 * (s1 - s0))
        ref = np.r_[0:nr, s1 - s0 - nr : s1 - s0]
        A = np.stack([np.ones_like(x), x, x * x], 1)
        block = grey[rows, s0:s1].astype(np.float32)
        # each row less its quadratic through the reference columns: one product with the hat
        # matrix that maps the reference columns to the fit on every column
        hat = A @ np.linalg.solve(A[ref].T @ A[ref], A[ref].T)
        res = block - block[:, ref] @ hat.T.astype(np.float32)  # grey levels: float32 holds them
        rms = np.sqrt(np.mean(res[:, ref] ** 2, axis=1))
        ok = (rms <= max(3.0 * median(rms), 2.0)) & (block.max(axis=1) < peak - 0.5)
        rows, res = rows[ok], res[ok][:, nr + m : nr + m + bw]
        above = rows < yc
        if above.all() or not above.any():  # one side only: its nearer and its further half
            near = np.abs(rows - yc) < float(np.median(np.abs(rows - yc)))
            groups = (near, ~near)
        else:
            groups = (above, ~above)
        if min(int(g.sum()) for g in groups) < MIN_ROWS:
            continue
        meds, floors = [], []
        for g in groups:
            cols = np.ascontiguousarray(res[g].T)  # a row per column: the medians along rows
            med = median_rows(cols)
            se = 1.4826 * median_rows(np.abs(cols - med[:, None])) / math.sqrt(int(g.sum()))
            meds.append(med)
            floors.append(np.maximum(SIGNIFICANCE * se, MIN_LEVEL))
        lo, hi = np.minimum(meds[0], meds[1]), np.maximum(meds[0], meds[1])
        seen = (
            (meds[0] > floors[0]) & (meds[1] > floors[1]) & (hi - lo <= np.maximum(AGREEMENT * hi, MIN_LEVEL))
        )
        level = np.where(seen, 0.5 * (meds[0] + meds[1]), 0.0)
        out[bx : bx + bw] = np.maximum(out[bx : bx + bw], level)
    return out if out.any() else None


def fit_smeared(
    grey: np.ndarray,
    lens: FisheyeLens,
    centre: tuple[float, float, float],
    peak: float,
    opts: GlareOptions,
    smear: np.ndarray | None,
    up_cam: np.ndarray | None = None,
    radiometry: Radiometry | None = None,
) -> GlareFit | None:
    """:func:`.glare.fit_glare` of the glare at ``centre`` (x, y, rough radius; px) with the
    column ``smear`` taken off (``up_cam``, ``radiometry``: as there).  Where the smear exceeds the rim's depth under the clip, the
    clip hides the rim in those columns and their rays are lost; when too few are left (a
    small glare under a strong smear), the glare is measured with the smear left in, as it
    was before it was estimated (its level is the same above and below the glare)."""
    x, y, r = centre
    fit = fit_glare(grey, lens, x, y, r, peak, opts, up_cam=up_cam, radiometry=radiometry, smear=smear)
    if fit is None and smear is not None:
        fit = fit_glare(grey, lens, x, y, r, peak, opts, up_cam=up_cam, radiometry=radiometry)
    return fit
