"""A glare's rim as a circle in a blend of the sky's metric and the sensor's.

Part of a real sun glare is atmospheric (the aureole: round on the sky, about the sun's
direction), part is the optics' (veiling glare and bloom of the lens: round on the sensor,
about the sun's image).  Near the rim each part falls steeply with its own distance, so the
rim, an isophote of their sum, is where a blend of the two distances is constant:

    alpha * s * |p - pi(a)| + (1 - alpha) * angle(v, a) = rho

(``v``, ``p``: a rim point's direction and pixel; ``a``: the sun's direction; ``pi``: the
lens's projection; ``s``: the lens's local scale, rad per pixel, at ``pi(a)``).  Near the
centre of the field the two distances agree and ``alpha`` does not matter; near its edge the
fisheye squeezes a disk round on the sky into an ellipse on the sensor and stretches a disk
round on the sensor into an egg on the sky, and the rim's shape tells ``alpha``.  Four
parameters, none of them free harmonics: a rim that is only partly seen (the horizon, a
cloud, a bloom column) still fixes its centre, which a model with free ellipse and egg terms
does not (they trade with the centre when an arc is missing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .lens import FisheyeLens
from .small import clip_unit, median, solve_spd
from .sphere import Vec3, tangent_frame

#: Prior on the blend (0: all on the sky, 1: all on the sensor), and its one-sigma width:
#: neutral, so that it only decides where the rim cannot (near the centre of the field).
ALPHA_PRIOR = 0.5
ALPHA_SIGMA = 0.5


@dataclass
class BlendFit:
    """A rim fitted in the blended metric (angles in radians)."""

    axis: np.ndarray  # unit sun direction, camera frame
    rho: float  # the rim's blended radius
    alpha: float  # 0: round on the sky .. 1: round on the sensor
    inliers: np.ndarray  # mask over the rim points
    rms: float  # of the inliers' residuals
    residuals: np.ndarray  # of every rim point


def _probe(lens: FisheyeLens, a: Vec3, h: float = 1e-4):
    """The tangent frame at ``a``, its image ``pi(a)`` and the image's motion per radian of
    turn along e1, e2 (a (2, 2) array, by differences over ``h``); None if behind the lens."""
    e1, e2 = tangent_frame(*a)
    out = []
    for p in (a, [ai + h * ei for ai, ei in zip(a, e1)], [ai + h * ei for ai, ei in zip(a, e2)]):
        n = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        c = lens.project_one(p[0] / n, p[1] / n, p[2] / n)
        if c is None:
            return None
        out.append(c)
    (u0, v0), (u1, v1), (u2, v2) = out
    return e1, e2, (u0, v0), np.array([[(u1 - u0) / h, (v1 - v0) / h], [(u2 - u0) / h, (v2 - v0) / h]])


def _refine(lens, v, uv, a, inl, k, floor, iters, s, alpha):
    """Gauss-Newton on (axis, rho, alpha) over the inliers ``inl``, then median / MAD
    reselection, ``iters`` times; ``s``: the lens's scale (rad per px).

    Each step solves the normal equations of the inliers' residuals and the prior on
    ``alpha``; in floats where the values are few (the fit runs ~10 steps per pass)."""
    rho = median(np.arccos(clip_unit(v[inl] @ a)))
    a = tuple(a.tolist())
    got = _probe(lens, a)
    if got is None:
        return None
    res = np.zeros(len(v))
    for i in range(iters + 1):
        vi, uvi = v[inl], uv[inl]
        # d residual / d (turn along e1, e2; rho; alpha), then the residual: one product
        # gives the normal equations and the residuals' sum of squares
        Jr = np.empty((len(vi), 5))
        Jr[:, 2] = -1.0
        for _ in range(3):  # Gauss-Newton on the current inliers
            e1, e2, c, dc = got
            cos_e = vi @ np.array([a, e1, e2]).T  # cos of the distance, then along e1, e2
            cos_d = clip_unit(cos_e[:, 0])
            d_ang = np.arccos(cos_d)
            sin_d = np.maximum(np.sqrt(1.0 - cos_d * cos_d), 1e-9)
            dp = uvi - c
            d_pix = np.maximum(np.hypot(dp[:, 0], dp[:, 1]), 1e-9)
            r = Jr[:, 4]
            np.subtract(alpha * s * d_pix + (1.0 - alpha) * d_ang, rho, out=r)
            Jr[:, :2] = (dp @ (-(alpha * s) * dc.T)) / d_pix[:, None] - cos_e[:, 1:] * (
                (1.0 - alpha) / sin_d
            )[:, None]
            Jr[:, 3] = s * d_pix - d_ang
            N = (Jr.T @ Jr).tolist()
            # the prior on alpha, weighed like one rim point at the fit's noise
            w = max(floor, math.sqrt(N[4][4] / len(r))) / ALPHA_SIGMA
            M = [row[:4] for row in N[:4]]
            M[3][3] += w * w
            g = [-N[0][4], -N[1][4], -N[2][4], -N[3][4] - w * w * (alpha - ALPHA_PRIOR)]
            step = solve_spd(M, g)
            if step is None:
                A = np.vstack([Jr[:, :4], [0.0, 0.0, 0.0, w]])
                b = np.concatenate([-r, [-w * (alpha - ALPHA_PRIOR)]])
                step = np.linalg.lstsq(A, b, rcond=None)[0].tolist()
            t1, t2, d_rho, d_alpha = step
            x, y, z = (a[j] + t1 * e1[j] + t2 * e2[j] for j in range(3))
            n = math.sqrt(x * x + y * y + z * z)
            a = (x / n, y / n, z / n)
            rho += d_rho
            alpha = min(max(alpha + d_alpha, 0.0), 1.0)
            got = _probe(lens, a)
            if got is None:
                return None
            if abs(t1) + abs(t2) < 0.2 * floor:
                break
        dp = uv - got[2]
        d_pix = np.maximum(np.hypot(dp[:, 0], dp[:, 1]), 1e-9)
        res = alpha * s * d_pix + (1.0 - alpha) * np.arccos(clip_unit(v @ np.array(a))) - rho
        if i == iters:
            break
        mid = median(res[inl])
        mad = 1.4826 * median(np.abs(res[inl] - mid))
        new = np.abs(res - mid) <= k * max(mad, floor)
        if new.sum() < 6 or np.array_equal(new, inl):
            break
        inl = new
    rms = math.sqrt(float(res[inl] @ res[inl]) / int(inl.sum())) if inl.any() else float("inf")
    return BlendFit(np.array(a), rho, alpha, inl, rms, res)


def fit_blend(
    lens: FisheyeLens,
    v: np.ndarray,
    uv: np.ndarray,
    a0: np.ndarray,
    starts: list[np.ndarray],
    *,
    k: float = 3.0,
    floor_rad: float = 1e-5,
    iters: int = 4,
    alpha0: float = ALPHA_PRIOR,
    scale_rad: float | None = None,
) -> BlendFit | None:
    """Robust fit of rim points (directions ``v`` (N, 3), pixels ``uv`` (N, 2)) from the
    axis ``a0`` and each inlier mask of ``starts``; the start whose fit keeps the most points
    within five noise floors wins (else the lowest truncated squared residual), as in
    :func:`.sphere.fit_cone`.  ``alpha0``: where the blend starts (a previous fit's);
    ``scale_rad``: the lens's local scale near the glare (rad per px; computed if None)."""
    if scale_rad is None:
        c, ok = lens.project(a0[None, :])
        if not ok[0]:
            return None
        scale_rad = math.radians(lens.deg_per_px(float(c[0, 0]), float(c[0, 1])))
    s = scale_rad
    sols: list[BlendFit] = []
    tried: list[np.ndarray] = []
    for m in starts:
        if m.sum() < 6 or any(np.array_equal(m, t) for t in tried):
            continue
        tried.append(m)
        f = _refine(lens, v, uv, a0.copy(), m.copy(), k, floor_rad, iters, s, alpha0)
        if f is not None:
            sols.append(f)
    if not sols:
        return None
    tol = 5.0 * floor_rad
    good = [f for f in sols if f.rms <= tol]
    if good:
        return max(good, key=lambda f: int(f.inliers.sum()))
    return min(sols, key=lambda f: float(np.minimum(f.residuals**2, tol * tol).sum()))


def blended_excess(
    lens: FisheyeLens,
    a: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    phi: np.ndarray,
    chi: np.ndarray,
    alpha: float,
    scale_rad: float,
) -> np.ndarray:
    """How much farther each sample at (``phi``, ``chi``) about ``a`` (rays on the sphere,
    rad) lies from the glare's centre in the blended metric than on the sphere (rad,
    (n_phi, n_chi)).  A glare's level there is its profile at the blended distance; to
    first order ``P(chi) + P'(chi) * excess``, which :func:`.glare.fit_glare` removes before it
    reads the sky's asymmetry from rings cast on the sphere."""
    if alpha <= 0.0:
        return np.zeros((len(phi), len(chi)))
    t = np.cos(phi)[:, None, None] * e1 + np.sin(phi)[:, None, None] * e2
    dirs = np.cos(chi)[None, :, None] * a + np.sin(chi)[None, :, None] * t
    uv, ok = lens.project(dirs.reshape(-1, 3))
    c, okc = lens.project(a[None, :])
    if not okc[0]:
        return np.zeros((len(phi), len(chi)))
    d_pix = np.hypot(uv[:, 0] - c[0, 0], uv[:, 1] - c[0, 1]).reshape(len(phi), len(chi))
    exc = alpha * (scale_rad * d_pix - chi[None, :])
    return np.where(ok.reshape(exc.shape), exc, 0.0)
