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
from .small import median
from .sphere import tangent_basis

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


def _distances(lens: FisheyeLens, v: np.ndarray, uv: np.ndarray, a: np.ndarray, h: float = 1e-4):
    """Angular and pixel distances of the rim points from ``a`` and their derivatives with
    respect to small turns of ``a`` along its tangent basis; None if ``a`` is behind the lens."""
    e1, e2 = tangent_basis(a)
    probes = np.array([a, a + h * e1, a + h * e2])
    c, ok = lens.project(probes / np.linalg.norm(probes, axis=1, keepdims=True))
    if not ok.all():
        return None
    cos_d = np.clip(v @ a, -1.0, 1.0)
    d_ang = np.arccos(cos_d)
    sin_d = np.maximum(np.sqrt(1.0 - cos_d * cos_d), 1e-9)
    g_ang = np.empty((len(v), 2))
    np.divide(v @ e1, sin_d, out=g_ang[:, 0])
    np.divide(v @ e2, sin_d, out=g_ang[:, 1])
    np.negative(g_ang, out=g_ang)
    dp = uv - c[0]
    d_pix = np.maximum(np.hypot(dp[:, 0], dp[:, 1]), 1e-9)
    dc = (c[1:] - c[0]) / h  # (2, 2): the image's motion per radian of turn along e1, e2
    g_pix = -(dp @ dc.T) / d_pix[:, None]
    return e1, e2, c[0], d_ang, g_ang, d_pix, g_pix


def _refine(lens, v, uv, a, inl, k, floor, iters, s, alpha):
    """Gauss-Newton on (axis, rho, alpha) over the inliers ``inl``, then median / MAD
    reselection, ``iters`` times; ``s``: the lens's scale (rad per px)."""
    rho = median(np.arccos(np.clip(v[inl] @ a, -1.0, 1.0)))
    got = _distances(lens, v, uv, a)
    if got is None:
        return None
    res = np.zeros(len(v))
    for i in range(iters + 1):
        for _ in range(3):  # Gauss-Newton on the current inliers
            e1, e2, _, d_ang, g_ang, d_pix, g_pix = got
            res = alpha * s * d_pix + (1.0 - alpha) * d_ang - rho
            J = np.column_stack(
                [alpha * s * g_pix + (1.0 - alpha) * g_ang, -np.ones(len(v)), s * d_pix - d_ang]
            )
            # the prior on alpha, weighed like one rim point at the fit's noise
            sig = max(floor, float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else floor)
            A = np.vstack([J[inl], [0.0, 0.0, 0.0, sig / ALPHA_SIGMA]])
            b = np.concatenate([-res[inl], [-(sig / ALPHA_SIGMA) * (alpha - ALPHA_PRIOR)]])
            step, *_ = np.linalg.lstsq(A, b, rcond=None)
            a = a + step[0] * e1 + step[1] * e2
            a /= np.linalg.norm(a)
            rho += float(step[2])
            alpha = float(np.clip(alpha + step[3], 0.0, 1.0))
            got = _distances(lens, v, uv, a)
            if got is None:
                return None
            if abs(step[0]) + abs(step[1]) < 0.2 * floor:
                break
        res = alpha * s * got[5] + (1.0 - alpha) * got[3] - rho
        if i == iters:
            break
        mid = median(res[inl])
        mad = 1.4826 * median(np.abs(res[inl] - mid))
        new = np.abs(res - mid) <= k * max(mad, floor)
        if new.sum() < 6 or np.array_equal(new, inl):
            break
        inl = new
    rms = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else float("inf")
    return BlendFit(a, rho, alpha, inl, rms, res)


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
