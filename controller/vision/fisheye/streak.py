"""A saturated streak along the sensor's columns (bloom, or a strong CCD smear) leaving the
glare: where it is, so that the rim's rays that run into it are not used.

A sensor that spills charge both ways along its columns draws a streak above and below the
glare; one read out one way spills one way only (upwards, say), and hides that side of the
rim.  Either streak is as wide as the glare's saturated core (charge spills along the
columns it saturated) and stands on the core's centre column; a sunlit cloud edge next to
the sun may be saturated too, but is broken, narrow, off to one side or wide.
"""

from __future__ import annotations

import math

import numpy as np

from .lens import FisheyeLens

_SIN_50DEG = math.sin(math.radians(50))


def streak_sides(
    grey: np.ndarray, xc: float, yc: float, r: float, sat_level: float
) -> tuple[bool | None, bool | None]:
    """Whether a saturated vertical streak (bloom, or a strong CCD smear) leaves the glare
    upwards and downwards in the image: 1.6 to 2.6 radii above (below) its centre, the
    columns through it are saturated and those 1.5 to 2.5 radii aside are not (a streak,
    not a saturated cloud).  A side the image does not hold is None."""
    H, W = grey.shape
    x0, x1 = max(int(xc - 0.6 * r), 0), min(int(xc + 0.6 * r) + 1, W)
    sides: list[bool | None] = []
    for lo, hi in ((yc - 2.6 * r, yc - 1.6 * r), (yc + 1.6 * r, yc + 2.6 * r)):
        r0, r1 = max(int(lo), 0), min(int(hi) + 1, H)
        if r1 - r0 < 2 or x1 <= x0:
            sides.append(None)
            continue
        inner = float(np.median(grey[r0:r1, x0:x1].max(axis=1))) >= sat_level
        sides.append(inner and _clear_aside(grey, r0, r1, xc, 1.5 * r, 2.5 * r, sat_level, 0.2))
    return sides[0], sides[1]


def streak_sides_at_core(
    grey: np.ndarray, xc: float, yc: float, sat_level: float, short: bool = True
) -> tuple[bool | None, bool | None]:
    """:func:`streak_sides` around a known centre, with the glare's saturated core measured
    on its centre row (radius ``rc``, column ``xc``; the estimated centre may sit a pixel or
    two off it).  A streak leaves the core unbroken from 1 to 2 ``rc`` (in 90 % of the rows,
    for noise); or, one way only, it reaches at least 0.4 ``rc`` further along the core's
    column than the core does the other way (a short one: a sensor's spill is as long as
    the charge it has to shed).  Beyond the core it stands as a streak would
    (:func:`_streak_band`).  A sunlit cloud edge next to the sun is broken, narrow, off to
    one side or wide: on our broken-cloud suite, the looser test of :func:`streak_sides`
    (from 1.3 to 2 radii of the first pass's rim) flagged 22 frames as bloomed instead of
    10, and missed 14 of the 239 visible suns instead of 9."""
    H, W = grey.shape
    xc, rc = core_row(grey, xc, yc, sat_level)
    if rc < 1.5:
        return None, None
    x0, x1 = max(int(xc - 0.6 * rc), 0), min(int(xc + 0.6 * rc) + 1, W)
    sides: list[bool | None] = []
    for lo, hi in ((yc - 2.0 * rc, yc - rc), (yc + rc, yc + 2.0 * rc)):
        r0, r1 = int(round(lo)), int(round(hi)) + 1
        if r0 < 0 or r1 > H or r1 - r0 < 3:
            sides.append(None)
            continue
        unbroken = float(np.mean(grey[r0:r1, x0:x1].max(axis=1) >= sat_level)) >= 0.9
        sides.append(unbroken and _streak_band(grey, r0, r1, xc, rc, sat_level, away=lo > yc))
    if any(sides) or not short:
        return sides[0], sides[1]
    # a short streak one way: the core's column runs on past where it stops the other way
    y0 = int(round(yc))
    up, down = (_column_run(grey, x0, x1, y0, step, sat_level) for step in (-1, 1))
    for k, (far, near) in enumerate(((up, down), (down, up))):
        reach = max(near, rc)
        if far - reach < 0.4 * rc:
            continue
        r0, r1 = (y0 - far, y0 - int(reach) + 1) if k == 0 else (y0 + int(reach), y0 + far + 1)
        if r1 - r0 >= 2 and _streak_band(grey, r0, r1, xc, rc, sat_level, away=k == 1):
            return (True, False) if k == 0 else (False, True)
    return sides[0], sides[1]


def _streak_band(
    grey: np.ndarray, r0: int, r1: int, xc: float, rc: float, sat_level: float, away: bool
) -> bool:
    """Whether the saturated pixels of rows ``r0:r1`` (beside the core; ``away``: ordered
    away from it) stand as a streak from a core of radius ``rc`` on column ``xc`` would:
    centred on that column (within ``rc / 4``, in the median row), in the third of the band
    nearest the core at least 0.8 ``rc`` wide (charge spills along the columns the core
    saturated), and nothing saturated 1.2 to 2.5 ``rc`` aside."""
    W = grey.shape[1]
    c0, c1 = max(int(xc - 1.2 * rc), 0), min(int(xc + 1.2 * rc) + 1, W)
    sat = grey[r0:r1, c0:c1] >= sat_level
    sat[:, 1:-1] |= sat[:, :-2] | sat[:, 2:]  # bridge single noisy pixels
    n = np.maximum(sat.sum(axis=1), 1)
    cols = np.arange(c0, c1, dtype=float)
    centred = float(np.median(np.abs((sat * cols).sum(axis=1) / n - xc))) <= 0.25 * rc
    base = (n if away else n[::-1])[: max((r1 - r0) // 3, 1)]
    wide = float(np.median(base)) >= 0.8 * rc
    return centred and wide and _clear_aside(grey, r0, r1, xc, 1.2 * rc, 2.5 * rc, sat_level, 0.05)


def _column_run(grey: np.ndarray, x0: int, x1: int, y0: int, step: int, sat_level: float) -> int:
    """How many rows from ``y0``, going ``step`` (-1 up, +1 down), columns ``x0:x1`` stay
    saturated somewhere (a single unsaturated row is bridged, for noise)."""
    rows = grey[:y0][::-1, x0:x1] if step < 0 else grey[y0 + 1 :, x0:x1]
    if rows.size == 0:
        return 0
    sat = rows.max(axis=1) >= sat_level
    ends = np.flatnonzero(~sat[:-1] & ~sat[1:])  # two unsaturated rows in a row end the run
    hit = np.flatnonzero(sat[: ends[0] if ends.size else sat.size])
    return int(hit[-1]) + 1 if hit.size else 0


def core_row(grey: np.ndarray, xc: float, yc: float, sat_level: float) -> tuple[float, float]:
    """The saturated run through (``xc``, ``yc``) along its row (single unsaturated pixels
    bridged): its centre and half its length (px), the core's column and radius, which a
    vertical streak leaves alone; (``xc``, 0) when the point is not saturated."""
    H, W = grey.shape
    y, x = int(round(yc)), int(round(xc))
    if not (0 <= y < H and 0 <= x < W):
        return xc, 0.0
    sat = grey[y] >= sat_level
    sat[1:-1] |= sat[:-2] & sat[2:]
    if not sat[x]:
        return xc, 0.0
    off = np.flatnonzero(~sat)
    left = off[off < x]
    right = off[off > x]
    a = int(left[-1]) + 1 if left.size else 0
    b = int(right[0]) if right.size else W
    return 0.5 * (a + b - 1), 0.5 * (b - a)


def _clear_aside(
    grey: np.ndarray,
    r0: int,
    r1: int,
    xc: float,
    d_in: float,
    d_out: float,
    sat_level: float,
    max_frac: float,
) -> bool:
    """Whether less than ``max_frac`` of rows ``r0:r1`` is saturated from ``d_in`` to
    ``d_out`` px either side of column ``xc``."""
    W = grey.shape[1]
    aside = [
        grey[r0:r1, max(int(a), 0) : min(int(b) + 1, W)]
        for a, b in ((xc - d_out, xc - d_in), (xc + d_in, xc + d_out))
    ]
    return all(float(np.mean(a >= sat_level)) < max_frac for a in aside if a.size)


def streak_way(sides: tuple[bool | None, bool | None]) -> float | None:
    """The glare's saturated streak from its sides (up, down): None without one; 0.0 when it
    leaves both ways (or the one way the image holds); -1.0 when it leaves upwards only,
    +1.0 downwards only (a sensor that spills one way)."""
    up, down = sides
    if up and down is False:
        return -1.0
    if down and up is False:
        return 1.0
    held = [s for s in (up, down) if s is not None]
    return 0.0 if held and all(held) else None


def streak_along(
    grey: np.ndarray, xc: float, yc: float, r: float, sat_level: float
) -> tuple[float | None, int]:
    """The glare's streak (:func:`streak_way` of :func:`streak_sides`) and the image axis it
    runs along: 1, the columns; else 0, the rows (a sensor read out across the stored image:
    a frame turned 90 deg, or a camera that writes its sensor's columns as rows).  The
    way's sign is the axis's: -1 towards the smaller coordinate (up, or left)."""
    way = streak_way(streak_sides(grey, xc, yc, r, sat_level))
    if way is not None:
        return way, 1
    return streak_way(streak_sides(grey.T, yc, xc, r, sat_level)), 0


def streak_along_at_core(
    grey: np.ndarray, xc: float, yc: float, sat_level: float
) -> tuple[float | None, int]:
    """:func:`streak_along` with :func:`streak_sides_at_core`; along the rows, not its short
    streak one way (``short``): a glare the lens squeezes along the image's radius is a core
    longer across it, and one a little longer on the horizon's side passed for one (the
    second renderer's linear look, suns near the top of the frame: 3 of 100 frames, one
    0.057 -> 0.102 deg off)."""
    way = streak_way(streak_sides_at_core(grey, xc, yc, sat_level))
    if way is not None:
        return way, 1
    return streak_way(streak_sides_at_core(grey.T, yc, xc, sat_level, short=False)), 0


#: a glare's rim rays: the lens, the axis ``a``, its tangents ``e1``, ``e2``, the rays' angles ``phi``, ``rho``
RimGeometry = tuple[FisheyeLens, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]


def streak_rays(geometry: RimGeometry, way: float | None, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """The rays a streak (:func:`streak_along`) leaves usable, ``geometry`` being
    :func:`rays_towards`'s ``(lens, a, e1, e2, phi, rho)`` (``e1`` near the camera's x): by
    design (a streak both ways takes the rays within 50 deg of its axis, not counted in the
    rim's gaps), and those also not running into a streak that leaves one way (counted:
    that side of the rim is unseen)."""
    phi = geometry[4]
    ok = np.abs(np.sin(phi) if axis else np.cos(phi)) < _SIN_50DEG if way == 0.0 else np.ones(len(phi), bool)
    return ok, ok & ~rays_towards(*geometry, way, axis) if way else ok


def short_bloom_both_ways(
    geometry: RimGeometry, chi: np.ndarray, has: np.ndarray, inliers: np.ndarray
) -> bool:
    """Whether a rim's misses are a short bloom's both ways along the image's columns: a
    sensor that spills a small glare's charge up and down its columns lengthens the glare
    there by a pixel or two, too little for a streak (:func:`streak_sides_at_core`), but on
    a rim a few pixels wide enough to push the rays within 50 deg of the vertical outwards.

    ``geometry``: the rim's :data:`RimGeometry`; ``chi``: each ray's rim (rad from the
    axis), ``has``: whether it found one, ``inliers``: whether the fit kept it.  True when,
    up and down alike, at least a third of the rays within 50 deg of the vertical found a
    rim the fit did not keep beyond the fitted radius, and at least 80 % of the others were
    kept (the fourth renderer's high suns, rims of 4 px: 29-33 of 48 rays kept, its two
    cones' rays out; docs/fisheye.md, step 7).  A cloud's fleck is rough all round, and a
    cloud's edge joined to a glare lies to one side."""
    lens, a, e1, e2, phi, rho = geometry
    up, down = (rays_towards(lens, a, e1, e2, phi, rho, dv, 1, 50.0) for dv in (-1.0, 1.0))
    across = ~(up | down)
    out = has & ~inliers & (chi > rho)
    if not (up.any() and down.any() and across.any()):
        return False
    return bool(np.mean(out[up]) >= 1 / 3 and np.mean(out[down]) >= 1 / 3 and np.mean(inliers[across]) >= 0.8)


def rays_towards(
    lens: FisheyeLens,
    a: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    phi: np.ndarray,
    rho: float,
    dv: float,
    axis: int = 1,
    half_width_deg: float = 40.0,
) -> np.ndarray:
    """The rays (angles ``phi`` about ``a``) whose rim lies within ``half_width_deg`` of the
    image's ``axis`` (1: vertical, 0: horizontal), towards the smaller coordinate (``dv`` <
    0: up, left) or the larger (``dv`` > 0), from the glare's centre."""
    pts = math.cos(rho) * a + math.sin(rho) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    uv, _ = lens.project(np.vstack([a[None, :], pts]))
    d = uv[1:] - uv[0]
    return dv * d[:, axis] > math.cos(math.radians(half_width_deg)) * np.hypot(d[:, 0], d[:, 1])
