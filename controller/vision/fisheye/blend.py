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
from collections import deque
from dataclasses import dataclass

import numpy as np

from .lens import FisheyeLens
from .small import median, solve_spd
from .sphere import Vec3, tangent_frame

#: Prior on the blend (0: all on the sky, 1: all on the sensor), and its one-sigma width:
#: neutral, so that it only decides where the rim cannot (near the centre of the field).
ALPHA_PRIOR = 0.5
ALPHA_SIGMA = 0.5
#: A camera's blend, once learned (:class:`LearnedBlend`): from the accepted fits whose rim
#: alone fixes it within LEARN_SIGMA, one every STEP_S (s) at most, the last KEEP (a day of
#: 30-s frames: a field camera's frames a second apart do not shorten its memory), at least
#: MIN_LEARNED of them within BAND_DEG of the glare's angle off the optical axis; the learned
#: prior is LEARNED_SIGMA wide (the spread of a clear day's fits in such a band on the third
#: renderer; 0.03 and 0.1 read its clouds worse: docs/fisheye-rounds.md, a thirtieth round)
LEARN_SIGMA, MIN_LEARNED, KEEP, STEP_S, BAND_DEG, LEARNED_SIGMA = 0.1, 5, 1000, 30.0, 4.0, 0.05


@dataclass
class BlendFit:
    """A rim fitted in the blended metric (angles in radians)."""

    axis: np.ndarray  # unit sun direction, camera frame
    rho: float  # the rim's blended radius
    alpha: float  # 0: round on the sky .. 1: round on the sensor
    inliers: np.ndarray  # mask over the rim points
    rms: float  # of the inliers' residuals
    residuals: np.ndarray  # of every rim point
    alpha_sigma: float = math.inf  # the blend's one-sigma from the rim alone (no prior)


def _probe(lens: FisheyeLens, a: Vec3):
    """The tangent frame at ``a``, its image ``pi(a)`` and the image's motion per radian of
    turn along e1, e2 (((du, dv) along e1), (du, dv) along e2)); None if behind the lens."""
    e1, e2 = tangent_frame(*a)
    got = lens.project_one_moving(a, e1, e2)
    if got is None:
        return None
    return e1, e2, got[0], got[1]


def _refine(lens, XT, a, inl, k, floor, iters, s, alpha, prior=(ALPHA_PRIOR, ALPHA_SIGMA)):
    """Gauss-Newton on (axis, rho, alpha) over the inliers ``inl``, then median / MAD
    reselection, ``iters`` times; ``XT``: the rim points as rows (x, y, z, u, v, 1) of a
    (6, N) array (directions, pixels); ``s``: the lens's scale (rad per px).

    Each step solves the normal equations of the inliers' residuals and the prior on
    ``alpha`` (``prior``: its mean and one-sigma); in floats where the values are few (the
    fit runs ~10 steps per pass), on arrays laid out by row, so that each quantity is one
    contiguous run."""
    got = _probe(lens, tuple(a.tolist()))
    if got is None:
        return None
    rho = median(_angles(XT[:, inl], a, *got[:2]))
    a = tuple(a.tolist())
    res = np.zeros(XT.shape[1])
    for i in range(iters + 1):
        Xi = XT[:, inl]
        n = Xi.shape[1]
        # d residual / d (turn along e1, e2; rho; alpha), then the residual: one product
        # gives the normal equations and the residuals' sum of squares
        JT = np.empty((5, n))
        JT[2] = -1.0
        unit = np.empty((4, n))  # the pixel offset's direction, then the tangent's
        for _ in range(3):  # Gauss-Newton on the current inliers
            e1, e2, c, dc = got
            Q = _frame_rows(a, e1, e2, c) @ Xi  # cos to a, e1, e2; pixel offset from pi(a)
            sin_d = np.hypot(Q[1], Q[2])
            d_ang = np.arctan2(sin_d, Q[0])
            np.maximum(sin_d, 1e-9, out=sin_d)
            d_pix = np.maximum(np.hypot(Q[3], Q[4]), 1e-9)
            np.divide(Q[3:5], d_pix, out=unit[:2])
            np.divide(Q[1:3], sin_d, out=unit[2:])
            g_s, g_a = -alpha * s, alpha - 1.0
            G = [[g_s * dc[0][0], g_s * dc[0][1], g_a, 0.0], [g_s * dc[1][0], g_s * dc[1][1], 0.0, g_a]]
            np.matmul(G, unit, out=JT[:2])
            np.multiply(d_pix, s, out=JT[3])
            JT[3] -= d_ang
            r = JT[4]
            np.multiply(JT[3], alpha, out=r)  # alpha * s * d_pix + (1 - alpha) * d_ang - rho
            r += d_ang
            r -= rho
            N = (JT @ JT.T).tolist()
            # the prior on alpha, weighed like one rim point at the fit's noise
            w = max(floor, math.sqrt(N[4][4] / n)) / prior[1]
            M = [row[:4] for row in N[:4]]
            M[3][3] += w * w
            g = [-N[0][4], -N[1][4], -N[2][4], -N[3][4] - w * w * (alpha - prior[0])]
            step = solve_spd(M, g)
            if step is None:
                A = np.vstack([JT[:4].T, [0.0, 0.0, 0.0, w]])
                b = np.concatenate([-r, [-w * (alpha - prior[0])]])
                step = np.linalg.lstsq(A, b, rcond=None)[0].tolist()
            t1, t2, d_rho, d_alpha = step
            x, y, z = (a[j] + t1 * e1[j] + t2 * e2[j] for j in range(3))
            nrm = math.sqrt(x * x + y * y + z * z)
            a = (x / nrm, y / nrm, z / nrm)
            rho += d_rho
            alpha = min(max(alpha + d_alpha, 0.0), 1.0)
            got = _probe(lens, a)
            if got is None:
                return None
            if abs(t1) + abs(t2) < 0.2 * floor:
                break
        Q = _frame_rows(a, *got[:3]) @ XT
        res = alpha * s * np.hypot(Q[3], Q[4]) + (1.0 - alpha) * np.arctan2(np.hypot(Q[1], Q[2]), Q[0]) - rho
        if i == iters:
            break
        r_in = res[inl]
        mid = median(r_in)
        mad = 1.4826 * median(np.abs(r_in - mid))
        new = np.abs(res - mid) <= k * max(mad, floor)
        if np.count_nonzero(new) < 6 or (new == inl).all():
            break
        inl = new
    rms = math.sqrt(float(res[inl] @ res[inl]) / int(inl.sum())) if inl.any() else float("inf")
    return BlendFit(np.array(a), rho, alpha, inl, rms, res, _alpha_sigma(N, max(rms, floor)))


def _alpha_sigma(N: list[list[float]], noise: float) -> float:
    """The blend's one-sigma from the rim points alone: ``noise`` (rad) times the root of the
    alpha entry of the inverse of their normal matrix (``N``'s first four rows and columns,
    without the prior); infinite where the rim does not fix it."""
    try:
        cov = np.linalg.inv(np.array([row[:4] for row in N[:4]]))
    except np.linalg.LinAlgError:
        return math.inf
    v = float(cov[3, 3])
    return noise * math.sqrt(v) if v > 0.0 and math.isfinite(v) else math.inf


def _frame_rows(a: Vec3, e1: Vec3, e2: Vec3, c: tuple[float, float]) -> np.ndarray:
    """The (5, 6) map from rim points' rows (x, y, z, u, v, 1) to their cosines along
    ``a``, ``e1``, ``e2`` and their pixel offsets from ``c``."""
    return np.array(
        [
            [a[0], a[1], a[2], 0.0, 0.0, 0.0],
            [e1[0], e1[1], e1[2], 0.0, 0.0, 0.0],
            [e2[0], e2[1], e2[2], 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0, 0.0, -c[0]],
            [0.0, 0.0, 0.0, 0.0, 1.0, -c[1]],
        ]
    )


def _angles(XT: np.ndarray, a, e1, e2) -> np.ndarray:
    """Angles (rad) of the points' directions (rows 0-2 of ``XT``) from ``a``."""
    Q = np.array([a, e1, e2]) @ XT[:3]
    return np.arctan2(np.hypot(Q[1], Q[2]), Q[0])


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
    prior: tuple[float, float] = (ALPHA_PRIOR, ALPHA_SIGMA),
) -> BlendFit | None:
    """Robust fit of rim points (directions ``v`` (N, 3), pixels ``uv`` (N, 2)) from the
    axis ``a0`` and each inlier mask of ``starts``; the start whose fit keeps the most points
    within five noise floors wins (else the lowest truncated squared residual), as in
    :func:`.sphere.fit_cone`.  ``alpha0``: where the blend starts (a previous fit's);
    ``scale_rad``: the lens's local scale near the glare (rad per px; computed if None);
    ``prior``: the blend's prior (mean, one-sigma; a camera's own once learned)."""
    if scale_rad is None:
        c, ok = lens.project(a0[None, :])
        if not ok[0]:
            return None
        scale_rad = math.radians(lens.deg_per_px(float(c[0, 0]), float(c[0, 1])))
    s = scale_rad
    XT = np.empty((6, len(v)))  # rows x, y, z, u, v, 1 (see _refine)
    XT[:3], XT[3:5], XT[5] = v.T, uv.T, 1.0
    sols: list[BlendFit] = []
    tried: list[np.ndarray] = []
    for m in starts:
        if m.sum() < 6 or any(np.array_equal(m, t) for t in tried):
            continue
        tried.append(m)
        f = _refine(lens, XT, a0.copy(), m.copy(), k, floor_rad, iters, s, alpha0, prior)
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


class LearnedBlend:
    """A camera's blend, learned from its own accepted fits, by the angle off the optical axis
    (the lens's squeeze, and so what the blend does to a rim, grows with it).

    Near the centre of the field the rim cannot tell the two metrics apart and the neutral
    prior decides; near the edge one frame can, but a cloud's light on one side of the rim
    reads as a blend too (the third renderer's cloudy suns: alpha 0 -> 1 and 0.5-0.9 deg low,
    docs/fisheye-rounds.md, a thirtieth round).  So the fits whose rim alone fixes the blend
    within :data:`LEARN_SIGMA` are kept (one every :data:`STEP_S`, the last :data:`KEEP`), and
    the median of those within :data:`BAND_DEG` of a glare's angle off the axis, weighted by
    their precision, is its prior, :data:`LEARNED_SIGMA` wide, once :data:`MIN_LEARNED` of
    them; before, the neutral one.  With the site only (:class:`.default.FisheyeEstimator`), as the sky models' cloud
    edges: without its ephemeris gate, rims that the prior makes regular include suns dimmed
    by a cloud and read 1.2-1.8 deg off (the third renderer's clouds without the site: 5
    false detections where there had been 1).
    """

    def __init__(self) -> None:
        self._fits: deque[tuple[float, float, float]] = deque(maxlen=KEEP)
        self._last_t = -math.inf

    def prior(self, d_cam: np.ndarray) -> tuple[float, float]:
        """The blend's prior (mean, one-sigma) for a glare in the direction ``d_cam`` (a unit
        vector, camera frame: z the optical axis)."""
        if len(self._fits) < MIN_LEARNED:
            return ALPHA_PRIOR, ALPHA_SIGMA
        th, a, s = np.array(self._fits).T
        near = np.abs(th - _off_axis_deg(d_cam)) <= BAND_DEG
        if int(np.count_nonzero(near)) < MIN_LEARNED:
            return ALPHA_PRIOR, ALPHA_SIGMA
        a, s = a[near], s[near]
        order = np.argsort(a)
        w = np.cumsum(1.0 / s[order] ** 2)
        return float(a[order][np.searchsorted(w, 0.5 * w[-1])]), LEARNED_SIGMA

    def observe(self, d_cam: np.ndarray, alpha: float, sigma: float, t: float) -> None:
        """An accepted fit's axis (camera frame), its blend, the blend's one-sigma from the rim
        alone, and the frame's time (POSIX s)."""
        if sigma <= LEARN_SIGMA and not t - self._last_t < STEP_S:
            self._fits.append((_off_axis_deg(d_cam), alpha, sigma))
            self._last_t = t


def _off_axis_deg(d_cam: np.ndarray) -> float:
    """The angle (deg) of the unit vector ``d_cam`` from the optical axis (camera z)."""
    return math.degrees(math.acos(min(max(float(d_cam[2]), -1.0), 1.0)))
