"""Geometry on the unit sphere for the glare's rim: cones, tangent frames, sampling.

Directions are unit vectors in the camera frame (OpenCV axes).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .lens import FisheyeLens
from .small import median, solve_spd

SIN_1DEG = math.sin(math.radians(1.0))
COS_88DEG = math.cos(math.radians(88.0))


def plane_fit(VT: np.ndarray) -> tuple[np.ndarray, float]:
    """Plane a . v = c through unit vectors given as the columns of ``VT`` (3, N) (total
    least squares); a . mean > 0."""
    m = VT.sum(axis=1) / VT.shape[1]
    q = VT - m[:, None]
    _, vecs = np.linalg.eigh(q @ q.T)
    a = vecs[:, 0]
    if a @ m < 0:
        a = -a
    return a, float(a @ m)


def refine_cone(v: np.ndarray, inl: np.ndarray, k: float, floor_rad: float, iters: int):
    """Iterate plane fit / harmonic residuals / MAD selection from the inlier set ``inl``;
    returns (axis, cos radius, inliers, residuals rad, (c2, s2) rad).  The harmonics are
    fitted by their normal equations (``np.linalg.lstsq`` where those are near singular),
    on arrays laid out by row (each quantity one contiguous run: the points are few)."""
    VT = np.ascontiguousarray(v.T)
    a, c = plane_fit(VT[:, inl])
    B = np.empty((6, len(v)))  # 1, cos 2 psi, sin 2 psi, cos 3 psi, sin 3 psi; the angle
    B[0] = 1.0
    t = np.empty(len(v))
    for i in range(iters + 1):
        e1, e2 = tangent_frame(*a.tolist())
        Q = np.array([a, e1, e2]) @ VT
        np.arctan2(np.hypot(Q[1], Q[2]), Q[0], out=B[5])
        psi = np.arctan2(Q[2], Q[1])
        np.multiply(psi, 2.0, out=t)
        np.cos(t, out=B[1])
        np.sin(t, out=B[2])
        np.multiply(psi, 3.0, out=t)
        np.cos(t, out=B[3])
        np.sin(t, out=B[4])
        Bi = B[:, inl]
        N = (Bi @ Bi.T).tolist()
        coef = solve_spd([row[:5] for row in N[:5]], [row[5] for row in N[:5]])
        if coef is None:
            coef = np.linalg.lstsq(Bi[:5].T, Bi[5], rcond=None)[0].tolist()
        ell = coef[1:3]
        res = B[5] - np.array(coef) @ B[:5]
        if i == iters:
            break
        r_in = res[inl]
        mad = 1.4826 * median(np.abs(r_in - median(r_in)))
        new = np.abs(res) <= k * max(mad, floor_rad)
        if np.count_nonzero(new) < 6 or (new == inl).all():
            break
        inl = new
        a, c = plane_fit(VT[:, inl])
    return a, c, inl, res, np.array(ell)


def _ransac_circle(v: np.ndarray, floor_rad: float, n_hyp: int = 32) -> np.ndarray:
    """Inliers of the best circle through 3 of the points, the triples spread a third of the
    rim apart (deterministic): a start that a contiguous arc of outliers (a saturated cloud
    edge) cannot drag, since some triples miss it."""
    n = len(v)
    k = np.unique(np.linspace(0, n - 1, min(n_hyp, n)).astype(int))
    idx = np.stack([k, (k + n // 3) % n, (k + (2 * n) // 3) % n], 1)
    jitter = (np.arange(len(k)) * 7) % max(n // 6, 1)  # vary the spacing a little
    idx[:, 2] = (idx[:, 2] + jitter) % n
    p1, p2, p3 = v[idx[:, 0]], v[idx[:, 1]], v[idx[:, 2]]
    nrm = np.cross(p2 - p1, p3 - p1)
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 1e-12
    nrm = nrm[ok] / ln[ok, None]
    c = np.sum(nrm * p1[ok], axis=1)
    flip = c < 0
    nrm[flip], c[flip] = -nrm[flip], -c[flip]
    rho = np.arccos(np.clip(c, -1.0, 1.0))
    tol = np.maximum(4.0 * floor_rad, 0.02 * rho) * np.sin(np.maximum(rho, 1e-6))
    count = (np.abs(v @ nrm.T - c) <= tol).sum(axis=0)
    best = int(np.argmax(count))
    return np.abs(v @ nrm[best] - c[best]) <= tol[best]


def fit_cone(
    v: np.ndarray, *, k: float = 3.0, floor_rad: float = 1e-5, iters: int = 4
) -> tuple[np.ndarray, float, np.ndarray, float, np.ndarray]:
    """Robust small circle (or ellipse) through unit vectors ``v`` (N, 3).

    The plane fit gives the axis (an ellipse's centre too, by its symmetry); the angular
    residuals are modelled as ``rho + c2 cos(2 psi) + s2 sin(2 psi) + c3 cos(3 psi) + s3
    sin(3 psi)`` (``psi``: the point's angle about the axis), so a glare that the lens or
    the optics made elliptical, or egg-shaped (round in the image near its edge), is not
    mistaken for outliers.  Two starts are refined by median / MAD rejection, all points and
    a RANSAC circle; the one that keeps more points within five noise floors wins (else the
    lower truncated squared residual).

    Returns (axis, mean angular radius rad, inlier mask, rms of the inliers' residuals
    about the ellipse rad, (c2, s2) rad).
    """
    # the start that keeps the most points within a few noise floors wins; a partial arc
    # always fits well, so a fit of all the points that also fits is preferred
    tol = 5.0 * floor_rad
    sols = [refine_cone(v, np.ones(len(v), bool), k, floor_rad, iters)]
    first_inl, first_res = sols[0][2], sols[0][3]
    clean = first_inl.sum() / first_inl.size >= 0.9 and _rms(first_res, first_inl) <= tol
    if len(v) >= 12 and not clean:
        start = _ransac_circle(v, floor_rad)
        if start.sum() >= 6:
            sols.append(refine_cone(v, start, k, floor_rad, iters))
    rms_of = [_rms(r, i) for _, _, i, r, _ in sols]
    good = [j for j, r in enumerate(rms_of) if r <= tol]
    if good:
        best = max(good, key=lambda j: int(sols[j][2].sum()))
    else:
        best = int(np.argmin([float(np.minimum(r**2, tol * tol).sum()) for _, _, _, r, _ in sols]))
    a, c, inl, res, ell = sols[best]
    rho = math.acos(min(max(c, -1.0), 1.0))
    return a, rho, inl, _rms(res, inl), ell


def centre_move(moves: np.ndarray, cos_phi: np.ndarray, sin_phi: np.ndarray) -> tuple[float, float]:
    """How far radial moves ``moves`` (rad, outwards positive) of a rim's points at position
    angles ``phi`` (given by their cosines and sines) move its centre (rad): as the circle
    fitted to them, centre and radius free, moves (the least-squares centre of ``m = dr + dx
    cos phi + dy sin phi``), and as their first harmonic ``2 mean(m cos phi)`` (and sine) says.
    The two agree on a whole rim; on an arc the shared part of the moves goes to the radius,
    and what is left is carried into the centre the more the shorter the arc (the sky's
    correction on a rim whose horizon side is lost, the second renderer's wide glare at 18.5
    deg, 1280 x 960: 0.23 deg by the harmonic, 0.68 fitted; its fix 0.21 deg off).  Fewer
    than three points, or all on one line: a fitted move of 0."""
    a = np.column_stack([np.ones(moves.size), cos_phi, sin_phi])
    sol, _, rank, _ = np.linalg.lstsq(a, moves, rcond=None)
    fitted = math.hypot(float(sol[1]), float(sol[2])) if rank == 3 else 0.0
    return fitted, 2.0 * math.hypot(float(np.mean(moves * cos_phi)), float(np.mean(moves * sin_phi)))


def _rms(res: np.ndarray, keep: np.ndarray) -> float:
    """RMS of ``res[keep]`` (inf when none is kept), as ``np.sqrt(np.mean(...))`` sums it."""
    r = res[keep]
    return math.sqrt(float((r * r).sum()) / r.size) if r.size else math.inf


def tangent_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``a`` to a right-handed frame (e1 near the camera's x)."""
    e1, e2 = tangent_frame(*a.tolist())
    return np.array(e1), np.array(e2)


Vec3 = tuple[float, float, float]


def tangent_frame(ax: float, ay: float, az: float) -> tuple[Vec3, Vec3]:
    """:func:`tangent_basis` of the unit vector (``ax``, ``ay``, ``az``), in floats."""
    rx, ry = (1.0, 0.0) if abs(ax) < 0.9 else (0.0, 1.0)
    d = rx * ax + ry * ay
    x, y, z = rx - d * ax, ry - d * ay, -d * az
    n = math.sqrt(x * x + y * y + z * z)
    x, y, z = x / n, y / n, z / n
    return (x, y, z), (ay * z - az * y, az * x - ax * z, ax * y - ay * x)


#: grey levels under the frame's peak that count as saturated (``FisheyeOptions.sat_margin``)
CLIP_MARGIN = 4.0


def sample_sphere(
    grey: np.ndarray,
    lens: FisheyeLens,
    a: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    up_cam: np.ndarray | None,
    grids: list[tuple[np.ndarray, np.ndarray]],
    smear: tuple[np.ndarray, float, float] | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Bilinear samples of ``grey`` at directions ``cos(chi) a + sin(chi) (cos(phi) e1 +
    sin(phi) e2)`` for each (phi, chi) grid, with one projection through the lens.

    Returns per grid (values (n_phi, n_chi) with NaN behind the lens, ``sky`` mask: the
    sample looks at the sky, inside the frame).  ``smear``: ``(level, clip, hidden)``, a
    level per column (W,) (the column smear of :func:`.smear.column_smear`) taken off every
    pixel under ``clip``; a pixel at or over it (near saturation) is left as it is (its light, smear included,
    is unknown), or, in a column whose smear exceeds ``hidden``, unknown (NaN): the
    clip there may hide where the glare's own light crosses the rim's level.
    """
    H, W = grey.shape
    # the directions by component, each grid a (n_phi, n_chi) block of one flat run
    shapes = [(len(phi), len(chi)) for phi, chi in grids]
    X = np.empty((3, sum(p * c for p, c in shapes)))
    k = 0
    for (phi, chi), (n_p, n_c) in zip(grids, shapes):
        t = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2  # (n_p, 3): the rays' tangents
        out = X[:, k : k + n_p * n_c].reshape(3, n_p, n_c)
        np.multiply(t.T[:, :, None], np.sin(chi), out=out)
        out += a[:, None, None] * np.cos(chi)
        k += n_p * n_c
    u, v, okp = lens.project_xyz(X[0], X[1], X[2])
    if not okp.any():
        return [(np.full(sh, np.nan), np.zeros(sh, bool)) for sh in shapes]
    if not okp.all():
        u[~okp], v[~okp] = u[okp][0], v[okp][0]
    if up_cam is not None:
        sky = up_cam @ X > SIN_1DEG
    else:
        sky = X[2] > COS_88DEG
    sky &= okp & (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    # a float window of the frame that holds every sample
    m = 1
    u_lo, v_lo, u_hi, v_hi = float(u.min()), float(v.min()), float(u.max()), float(v.max())
    x0 = min(max(math.floor(u_lo) - m, 0), W - 1)
    y0 = min(max(math.floor(v_lo) - m, 0), H - 1)
    x1 = min(max(math.ceil(u_hi) + m + 1, x0 + 1), W)
    y1 = min(max(math.ceil(v_hi) + m + 1, y0 + 1), H)
    win = grey[y0:y1, x0:x1].astype(np.float32)
    if smear is not None:
        lev = smear[0][None, x0:x1]
        win = np.where(win < smear[1], win - lev, np.where(lev > smear[2], np.nan, win))
    mx = (u - x0).astype(np.float32).reshape(1, -1)
    my = (v - y0).astype(np.float32).reshape(1, -1)
    vals = np.empty(u.size, np.float32)
    for i in range(0, u.size, 30000):  # remap maps are limited to 32767 per side
        vals[i : i + 30000] = cv2.remap(
            win, mx[:, i : i + 30000], my[:, i : i + 30000], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        ).ravel()
    vals[~okp] = np.nan
    samples, k = [], 0
    for sh in shapes:
        n = sh[0] * sh[1]
        samples.append((vals[k : k + n].reshape(sh), sky[k : k + n].reshape(sh)))
        k += n
    return samples
