"""Geometry on the unit sphere for the glare's rim: cones, tangent frames, sampling.

Directions are unit vectors in the camera frame (OpenCV axes).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .lens import FisheyeLens

SIN_1DEG = math.sin(math.radians(1.0))
COS_88DEG = math.cos(math.radians(88.0))


def plane_fit(v: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted plane a . v = c through unit vectors (total least squares); a . mean > 0."""
    sw = w.sum()
    m = (w[:, None] * v).sum(0) / sw
    q = v - m
    C = (w[:, None] * q).T @ q
    _, vecs = np.linalg.eigh(C)
    a = vecs[:, 0]
    if a @ m < 0:
        a = -a
    return a, float(a @ m)


def fit_cone(v: np.ndarray, *, k: float = 3.0, floor_rad: float = 1e-5,
             iters: int = 4) -> tuple[np.ndarray, float, np.ndarray, float, np.ndarray]:
    """Robust small circle (or ellipse) through unit vectors ``v`` (N, 3).

    The plane fit gives the axis (an ellipse's centre too, by its symmetry); the angular
    residuals are modelled as ``rho + c2 cos(2 psi) + s2 sin(2 psi)`` (``psi``: the point's
    angle about the axis), so a glare that the lens or the optics made elliptical is not
    mistaken for outliers.

    Returns (axis, mean angular radius rad, inlier mask, rms of the inliers' residuals
    about the ellipse rad, (c2, s2) rad).
    """
    w = np.ones(len(v))
    a, c = plane_fit(v, w)
    inl = np.ones(len(v), bool)
    ell = np.zeros(2)
    res = np.zeros(len(v))
    for i in range(iters + 1):
        e1, e2 = tangent_basis(a)
        ang = np.arccos(np.clip(v @ a, -1.0, 1.0))
        psi = np.arctan2(v @ e2, v @ e1)
        A = np.stack([np.ones_like(psi), np.cos(2 * psi), np.sin(2 * psi)], 1)
        coef, *_ = np.linalg.lstsq(A[inl], ang[inl], rcond=None)
        ell = coef[1:3]
        res = ang - A @ coef
        if i == iters:
            break
        mad = 1.4826 * float(np.median(np.abs(res[inl] - np.median(res[inl]))))
        new = np.abs(res) <= k * max(mad, floor_rad)
        if new.sum() < 6 or np.array_equal(new, inl):
            break
        inl = new
        a, c = plane_fit(v[inl], w[inl])
    rho = float(np.arccos(np.clip(c, -1.0, 1.0)))
    rms = float(np.sqrt(np.mean(res[inl] ** 2))) if inl.any() else float("inf")
    return a, rho, inl, rms, ell


def tangent_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``a`` to a right-handed frame (e1 near the camera's x)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ a) * a
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def sample_sphere(grey: np.ndarray, lens: FisheyeLens, a: np.ndarray, e1: np.ndarray,
                   e2: np.ndarray, up_cam: np.ndarray | None,
                   grids: list[tuple[np.ndarray, np.ndarray]],
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Bilinear samples of ``grey`` at directions ``cos(chi) a + sin(chi) (cos(phi) e1 +
    sin(phi) e2)`` for each (phi, chi) grid, with one projection through the lens.

    Returns per grid (values (n_phi, n_chi) with NaN behind the lens, ``sky`` mask: the
    sample looks at the sky, inside the frame).
    """
    H, W = grey.shape
    blocks = []
    for phi, chi in grids:
        t = np.cos(phi)[:, None, None] * e1 + np.sin(phi)[:, None, None] * e2
        blocks.append(np.cos(chi)[None, :, None] * a + np.sin(chi)[None, :, None] * t)
    dirs = np.concatenate([b.reshape(-1, 3) for b in blocks])
    uv, okp = lens.project(dirs)
    if not okp.any():
        return [(np.full(b.shape[:2], np.nan), np.zeros(b.shape[:2], bool)) for b in blocks]
    uv[~okp] = uv[okp][0]
    if up_cam is not None:
        sky = dirs @ up_cam > SIN_1DEG
    else:
        sky = dirs[:, 2] > COS_88DEG
    sky &= okp & (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
    # a float window of the frame that holds every sample
    m = 1
    x0 = int(np.clip(np.floor(uv[:, 0].min()) - m, 0, W - 1))
    y0 = int(np.clip(np.floor(uv[:, 1].min()) - m, 0, H - 1))
    x1 = int(np.clip(np.ceil(uv[:, 0].max()) + m + 1, x0 + 1, W))
    y1 = int(np.clip(np.ceil(uv[:, 1].max()) + m + 1, y0 + 1, H))
    win = grey[y0:y1, x0:x1].astype(np.float32)
    mx = (uv[:, 0] - x0).astype(np.float32).reshape(1, -1)
    my = (uv[:, 1] - y0).astype(np.float32).reshape(1, -1)
    vals = np.empty(dirs.shape[0], np.float32)
    for i in range(0, dirs.shape[0], 30000):  # remap maps are limited to 32767 per side
        vals[i:i + 30000] = cv2.remap(win, mx[:, i:i + 30000], my[:, i:i + 30000], cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_REPLICATE).ravel()
    vals[~okp] = np.nan
    out, k = [], 0
    for b in blocks:
        n = b.shape[0] * b.shape[1]
        out.append((vals[k:k + n].reshape(b.shape[:2]), sky[k:k + n].reshape(b.shape[:2])))
        k += n
    return out
