"""The sky behind the glare: its asymmetry across the rim, measured in rings outside it.

A sky brighter on one side of the glare shifts that side's rim outwards (by the sky's
excess over the rim's slope), which would move the fitted centre by tenths of a degree; so
the rim's level is raised, ray by ray, by the sky's asymmetric part, estimated here.
"""

from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np

from .small import gradient, median, median_kept, median_rows


def harmonic(phi: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Robust fit m = m0 + c cos(phi) + s sin(phi) + quadrupole; returns (c, s)."""
    A = np.stack([np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)], 1)
    finite = np.isfinite(m)
    keep = finite
    coef = np.zeros(5)
    for _ in range(3):
        if keep.sum() < 12:
            return np.zeros(2)
        coef, *_ = np.linalg.lstsq(A[keep], m[keep], rcond=None)
        res = m - A @ coef
        mad = 1.4826 * median(np.abs(res[keep])) + 0.5
        new = finite & (np.abs(res) <= 3.0 * mad)
        if np.array_equal(new, keep):
            break
        keep = new
    return coef[1:3]


#: the rings' edges (rim radii) whose dipoles :func:`sky_dipole` fits, and whose sky
#: :func:`sky_by_elevation` models
RING_EDGES = (1.15, 1.4, 1.7, 2.0, 2.4, 2.8, 3.2)

#: rounds of clipping the elevation model's outliers (it stops once they stop changing)
MAX_CLIP_ROUNDS = 8


@lru_cache(maxsize=128)
def harmonic_design(phi_bytes: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The harmonics' design matrix for the ray angles (as bytes, to be cached: the same
    few ray sets recur frame after frame) and the transpose of its pseudo-inverse.  A glare
    casts 48-120 rays, so there are at most 73 sets (16 had missed on a third of the calls
    over the third renderer's 30 bench frames, each glare its own size)."""
    phi = np.frombuffer(phi_bytes)
    A = np.stack([np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)], 1)
    return A, np.linalg.pinv(A).T


def harmonics(phi: np.ndarray, M: np.ndarray) -> np.ndarray:
    """:func:`harmonic` for each row of ``M``; rows without gaps or outliers take one
    matrix product."""
    A, pinv_t = harmonic_design(np.ascontiguousarray(phi, dtype=np.float64).tobytes())
    out = np.zeros((M.shape[0], 2))
    clean = np.isfinite(M).all(axis=1)
    if clean.any():
        coef = M[clean] @ pinv_t
        res = M[clean] - coef @ A.T
        mad = 1.4826 * median_rows(np.abs(res)) + 0.5
        ok = (np.abs(res) <= 3.0 * mad[:, None]).all(axis=1)
        rows = np.flatnonzero(clean)
        out[rows[ok]] = coef[ok, 1:3]
        clean[rows[~ok]] = False
    rest = np.flatnonzero(~clean)
    if rest.size:
        try:
            out[rest] = _robust_rows(A, M[rest])
        except np.linalg.LinAlgError:  # a row's kept rays all but collinear: one by one
            for i in rest:
                out[i] = harmonic(phi, M[i])
    return out


def _robust_rows(A: np.ndarray, M: np.ndarray) -> np.ndarray:
    """:func:`harmonic` for every row of ``M`` at once (design ``A``: (n, 5)), each row's
    weighted normal equations solved in one batch: a ring with a streak or a cloud in it
    clips its outliers without a Python loop over rings.  Raises LinAlgError when a row's
    system is singular."""
    finite = np.isfinite(M)
    Mz = np.where(finite, M, 0.0)
    keep = finite.copy()
    out = np.zeros((M.shape[0], 2))
    active = np.ones(M.shape[0], bool)
    coef = np.zeros((M.shape[0], 5))
    for _ in range(3):
        few = active & (keep.sum(axis=1) < 12)  # too few rays left: no dipole
        out[few] = 0.0
        active &= ~few
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        w = keep[rows].astype(float)
        N = (A.T[None, :, :] * w[:, None, :]) @ A  # each row's A^T W A
        b = (w * Mz[rows]) @ A
        coef[rows] = np.linalg.solve(N, b[..., None])[..., 0]
        res = np.abs(Mz[rows] - coef[rows] @ A.T)
        mad = 1.4826 * median_kept(res, keep[rows]) + 0.5
        new = finite[rows] & (res <= 3.0 * mad[:, None])
        done = (new == keep[rows]).all(axis=1)
        out[rows] = coef[rows, 1:3]
        keep[rows] = new
        active[rows[done]] = False
    return out


def sky_dipole(
    vals: np.ndarray,
    chi: np.ndarray,
    phi: np.ndarray,
    rho: float,
    rays_ok: np.ndarray,
    contrast: float,
    sky: np.ndarray | None = None,
) -> np.ndarray:
    """The sky's dipole (grey levels along cos, sin of the ray angle) at the rim's radius.

    In rings outside the rim, the measured dipole is the sky's, ``k1 chi + k2 chi^2``, plus
    the glare's own profile shifted by the axis's error ``eps``: ``-P'(chi) eps``, with
    ``P'`` the radial derivative of the mean profile.  Solving for (eps, k1, k2) per
    component separates the two; only the sky's part at ``rho`` is returned (capped at a
    quarter of the glare's contrast).  ``sky`` (same shape as ``vals``) marks the samples that
    look at the sky (not the ground, not beyond the image circle); a ray's ring counts only
    when all its samples do, and a ring only when 75 % of the rays in ``rays_ok`` and 60 %
    of all its rays count (a streak's 22 % left out by design and a little ground had
    dropped every ring when 75 % of all rays were asked for).  ``chi``: the rings' radii
    (rad), ascending, as :func:`.glare.fit_glare` casts them.
    """
    if sky is None:
        sky = np.ones(vals.shape, bool)
    good = sky & rays_ok[:, None] & np.isfinite(vals)
    n_good = good.sum(axis=0)
    if n_good.sum() < 12:
        return np.zeros(2)
    prof = np.where(good, vals, 0.0).sum(axis=0) / np.maximum(n_good, 1)
    seen = n_good > 0
    if not seen.all():  # the mean profile (a ring seen nowhere: its mean)
        prof[~seen] = float(prof[seen].mean())
    dprof = gradient(prof, chi)
    # the rings' radii rise along ``chi``: each ring is a run of columns, all summed in one
    # reduction (sums over counts: the rings' means, in the samples' precision)
    cuts = np.searchsorted(chi, np.array(RING_EDGES) * rho)
    lo, hi = cuts[:-1], cuts[1:]
    wide = hi - lo >= 2
    if int(np.count_nonzero(wide)) < 4:
        return np.zeros(2)
    lo, hi = lo[wide], hi[wide]
    n = (hi - lo).astype(vals.dtype)
    at = np.stack([lo, hi], axis=1).ravel()  # [start, end) of each ring; the ends' sums unused
    R, C = vals.shape
    pad = np.zeros((R, C + 1), vals.dtype)
    pad[:, :C] = vals
    m = np.add.reduceat(pad, at, axis=1)[:, ::2] / n  # (rays, rings)
    sky_pad = np.ones((R, C + 1), bool)
    sky_pad[:, :C] = sky
    m[~rays_ok[:, None] | ~np.logical_and.reduceat(sky_pad, at, axis=1)[:, ::2]] = np.nan
    # a ring cut by the horizon: its dipole is unreliable (the rays left out by design, a
    # streak's, count against the ring only where it would be left too short)
    fin = np.isfinite(m)
    n_ok = int(np.count_nonzero(rays_ok))
    keep = np.count_nonzero(fin, axis=0) / R >= 0.6
    if n_ok:
        keep &= np.count_nonzero(fin & rays_ok[:, None], axis=0) / n_ok >= 0.75
    c = np.add.reduceat(np.append(chi, 0.0), at)[::2][keep].astype(float) / (hi - lo)[keep] / rho
    dp = np.add.reduceat(np.append(dprof, 0.0).astype(dprof.dtype), at)[::2][keep].astype(float)
    rows = np.stack([-dp / (hi - lo)[keep], c, c**2], axis=1)
    means = m[:, keep].T
    if len(rows) < 4:
        return np.zeros(2)
    rhs = harmonics(phi, np.ascontiguousarray(means))
    sol, *_ = np.linalg.lstsq(rows, rhs, rcond=None)  # (3, 2): eps, k1, k2 per axis
    dip = sol[1] + sol[2]
    cap = 0.25 * contrast
    nrm = float(np.linalg.norm(dip))
    return dip * (cap / nrm) if nrm > cap else dip


def sky_by_elevation(
    vals: np.ndarray,
    chi: np.ndarray,
    phi: np.ndarray,
    rho: float,
    rays_ok: np.ndarray,
    sky: np.ndarray,
    x: np.ndarray,
    contrast: float,
) -> np.ndarray | None:
    """The sky's asymmetry as a function of elevation, for a glare near the horizon.

    ``x``: each ring sample's elevation minus the axis's, over ``rho``.  Model of the ring
    means: a free level per ring, the glare's profile shifted by the axis's error
    (``-P'(chi) eps``), and ``c1 x + c2 x^2 + c3 x^3 + c4 x (chi / rho - 1)`` (the horizon's
    brightening, stronger towards the sun).  Works on the rings' sky part alone, so a ring
    cut by the horizon still counts.  Returns (c1, c2, c3) (the polynomial at the rim,
    grey levels) or None when there is too little sky.
    """
    good = sky & rays_ok[:, None] & np.isfinite(vals)
    if good.sum() < 30:
        return None
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        prof = np.nanmean(np.where(good, vals, np.nan), axis=0)
    if not np.isfinite(prof).all():
        return None
    dprof = gradient(prof, chi)
    # the rings' radii rise along ``chi``: each ring is a run of columns, reduced at once
    edges = np.searchsorted(chi, np.array(RING_EDGES) * rho)
    lo, hi = edges[:-1], edges[1:]
    wide = hi - lo >= 2
    at = np.stack([lo, hi], axis=1).ravel()
    R, C = vals.shape
    pad = np.zeros((R, C + 1))
    pad[:, :C] = np.where(good, vals, 0.0)  # the rings' sums (a ray counts where all its samples do)
    sums = np.add.reduceat(pad, at, axis=1)[:, ::2]
    pad[:, :C] = x
    xsums = np.add.reduceat(pad, at, axis=1)[:, ::2]
    good_pad = np.ones((R, C + 1), bool)
    good_pad[:, :C] = good
    ok = np.logical_and.reduceat(good_pad, at, axis=1)[:, ::2] & wide  # (rays, rings)
    used = np.flatnonzero(ok.sum(axis=0) >= 6)
    if used.size < 3:
        return None
    n = np.maximum(hi - lo, 1).astype(float)
    dp = np.add.reduceat(np.append(dprof, 0.0), at)[::2] / n
    sj = np.add.reduceat(np.append(chi, 0.0), at)[::2] / n / rho - 1.0
    # one row per (ring, ray) seen, ring by ring: a level per ring, the glare's shift, the sky
    okt = ok[:, used].T
    ring, ray = np.nonzero(okt)
    m = (sums[:, used] / n[used]).T[okt]
    xx = (xsums[:, used] / n[used]).T[okt]
    d = dp[used][ring]
    A = np.zeros((m.size, used.size + 6))
    A[np.arange(m.size), ring] = 1.0
    A[:, used.size :] = np.stack(
        [-d * np.cos(phi[ray]), -d * np.sin(phi[ray]), xx, xx**2, xx**3, xx * sj[used][ring]], axis=1
    )
    b = m
    # clipped until the kept samples stop changing: a cloud over a third of the outer rings,
    # still half in the fit after two rounds, had turned the horizon's brightening round
    # (the third renderer's broken cloud: suns under a clear line of sight found 0.9 deg low)
    keep = np.ones(len(b), bool)
    sol = np.zeros(A.shape[1])
    for _ in range(MAX_CLIP_ROUNDS):
        sol, *_ = np.linalg.lstsq(A[keep], b[keep], rcond=None)
        res = b - A @ sol
        mad = 1.4826 * median(np.abs(res[keep])) + 0.5
        new = np.abs(res) <= 3.0 * mad
        if np.array_equal(new, keep) or new.sum() < 2 * A.shape[1]:
            break
        keep = new
    c = sol[-4:-1]
    worst = float(np.abs(np.polyval([c[2], c[1], c[0], 0.0], np.linspace(-1, 1, 9))).max())
    cap = 0.25 * contrast
    return c * (cap / worst) if worst > cap else c


#: the air mass term of :func:`calibrated_scale` is held at this elevation's below it
MIN_CAL_EL = math.radians(5.0)


def calibrated_scale(
    cal: tuple[float, float, float, float] | None,
    by_elevation: bool,
    a: np.ndarray,
    up_cam: np.ndarray | None,
) -> float:
    """A camera's sky calibration ``(k0, k1)`` of the dipole, then of the model by elevation
    (:func:`controller.calibration.fisheye_sky_scale.fit_sky_calibration`), for the model in
    use, at the elevation of the axis ``a``: ``k0 + k1 (1 / sin(el) - 1)``, the air mass less
    one (held under 5 deg), kept within 0.25-4 (a sky scale's bounds).  1 without a
    calibration; ``k0`` without the vertical."""
    if cal is None:
        return 1.0
    k0, k1 = (cal[2], cal[3]) if by_elevation else (cal[0], cal[1])
    x = 0.0
    if up_cam is not None:
        x = 1.0 / math.sin(max(math.asin(float(np.clip(a @ up_cam, -1.0, 1.0))), MIN_CAL_EL)) - 1.0
    return float(np.clip(k0 + k1 * x, 0.25, 4.0))
