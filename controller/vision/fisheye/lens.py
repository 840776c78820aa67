"""The calibrated fisheye lens, pixel <-> direction, in OpenCV's ``cv2.fisheye`` model.

Camera frame: OpenCV's (x right, y down, z along the optical axis).  Directions are unit
vectors; the off-axis angle is ``theta = arccos(z)``.  The model (Kannala-Brandt) puts a ray
at the distorted radius ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4
theta^8)`` (times ``fx``, ``fy``) from the principal point.

Direction -> pixel is ``cv2.fisheye.projectPoints``'s formula, in front of the lens only
(z > 0: it works through ``tan(theta)``), written out in numpy: OpenCV's call spends about
90 ns a point (a rotation and its bookkeeping per point), five times the vectorised
formula, and a glare's rays are thousands of points a pass; the tests hold the two within
1e-10 px (the arrays' ``theta_d`` is summed by Horner's rule: within 1e-12 px; one
direction's, in floats, as OpenCV sums it, bit for bit).  Pixel -> direction inverts the
polynomial here, by Newton's method from a table, to ``THETA_LIMIT_DEG``:
``cv2.fisheye.undistortPoints`` clamps ``theta_d`` at pi / 2, so on a lens whose image
grows faster than the angle (stereographic, common on sky cameras) every ray past 76-78 deg
came back wrong (6 deg at 85 deg: a low sun's glare read 2.5 deg wide instead of 5.6, and no
rim found), and it folds rays past 90 deg on the others.
"""

from __future__ import annotations

import bisect
import math

import cv2
import numpy as np

#: Rays beyond this off-axis angle (deg) are not trusted (see the module's docstring).
THETA_LIMIT_DEG = 95.0
_NO_TURN = np.zeros(3)  # projectPoints' rotation and translation: none
_FEW = 8  # up to this many pixels, rays are computed in floats (numpy's overhead dominates)
_FEW_PROJECT = 4  # and up to this many directions, pixels


class FisheyeLens:
    """OpenCV fisheye intrinsics ``K`` (3 x 3) and ``D`` (k1..k4) of a ``width x height``
    image."""

    def __init__(self, K, D, width: int, height: int):
        self.K = np.asarray(K, np.float64).reshape(3, 3)
        self.D = np.asarray(D, np.float64).reshape(4, 1)
        self.width = int(width)
        self.height = int(height)
        self.fx, self.fy = float(self.K[0, 0]), float(self.K[1, 1])
        self.cx, self.cy = float(self.K[0, 2]), float(self.K[1, 2])
        self._f = math.sqrt(self.fx * self.fy)
        # theta_d over the field, up to where the polynomial stops rising (beyond, a radius
        # has no single ray): the inversion's table
        th = np.linspace(0.0, math.radians(THETA_LIMIT_DEG + 5.0), 2048)
        td = theta_d(th, self.D.ravel())
        falls = np.flatnonzero(np.diff(td) <= 0.0)
        n = int(falls[0]) + 1 if falls.size else th.size
        self._th_table, self._td_table = th[:n], td[:n]
        self._th_list, self._td_list = self._th_table.tolist(), self._td_table.tolist()
        self._td_max = float(self._td_table[-1])
        self._k = tuple(float(x) for x in self.D.ravel())
        self._skew = float(self.K[0, 1])
        self._alpha = self._skew / self.fx  # OpenCV's skew parameter
        self._theta_limit = math.radians(THETA_LIMIT_DEG)

    @classmethod
    def from_camera(cls, cam) -> FisheyeLens:
        """From a bundle's ``[camera]`` (:class:`controller.calibration.fisheye_bundle.FisheyeCamera`)."""
        return cls(cam.K, cam.dist, cam.width, cam.height)

    def scaled_to(self, width: int, height: int) -> FisheyeLens:
        """The same lens read out at another resolution (pixel centres scale about -0.5)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, 0] *= sx
        K[1, 1] *= sy
        K[0, 2] = (self.cx + 0.5) * sx - 0.5
        K[1, 2] = (self.cy + 0.5) * sy - 0.5
        return FisheyeLens(K, self.D, width, height)

    # -- pixel -> direction --------------------------------------------------------------
    def rays(self, uv) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) -> unit camera-frame directions (N, 3) and ``valid`` (N,)."""
        p = np.asarray(uv, np.float64).reshape(-1, 2)
        if p.shape[0] <= _FEW:  # the hot path (a candidate's centre, a local scale): floats
            out = [self._ray(float(u), float(v)) for u, v in p]
            return np.array([d for d, _ in out], float).reshape(-1, 3), np.array([ok for _, ok in out], bool)
        b = (p[:, 1] - self.cy) / self.fy
        a = (p[:, 0] - self.cx - self._skew * b) / self.fx
        td = np.hypot(a, b)
        theta = np.interp(td, self._td_table, self._th_table)
        for _ in range(2):  # the table's guess is within 0.05 deg: Newton converges at once
            theta = theta - (theta_d(theta, self._k) - td) / dtheta_d(theta, self._k)
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(td > 0, np.sin(theta) / td, 0.0)
        d = np.stack([a * scale, b * scale, np.cos(theta)], axis=1)
        valid = (td <= self._td_max) & np.isfinite(d).all(axis=1) & (theta <= self._theta_limit)
        return np.where(valid[:, None], d, np.nan), valid

    def _ray(self, u: float, v: float) -> tuple[tuple[float, float, float], bool]:
        """:meth:`rays` for one pixel, in floats."""
        b = (v - self.cy) / self.fy
        a = (u - self.cx - self._skew * b) / self.fx
        td = math.hypot(a, b)
        if not td <= self._td_max:
            return (math.nan, math.nan, math.nan), False
        tab = self._td_list
        i = min(max(bisect.bisect_right(tab, td), 1), len(tab) - 1)
        t0, t1 = tab[i - 1], tab[i]
        theta = self._th_list[i - 1] + (self._th_list[i] - self._th_list[i - 1]) * (td - t0) / (t1 - t0)
        for _ in range(2):  # the slope is positive where the table rises; kept off zero
            theta -= (float(theta_d(theta, self._k)) - td) / max(float(dtheta_d(theta, self._k)), 1e-12)
        if theta > self._theta_limit:
            return (math.nan, math.nan, math.nan), False
        if td == 0.0:
            return (0.0, 0.0, 1.0), True
        scale = math.sin(theta) / td
        return (a * scale, b * scale, math.cos(theta)), True

    def ray(self, u: float, v: float) -> np.ndarray:
        d, _ = self.rays([[u, v]])
        return d[0]

    # -- direction -> pixel --------------------------------------------------------------
    def project(self, dirs) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame directions (N, 3) -> pixels (N, 2); ``valid`` only in front (z > 0;
        the others are put at the principal point)."""
        d = np.asarray(dirs, np.float64).reshape(-1, 3)
        if d.shape[0] <= _FEW_PROJECT:  # the hot path's single directions: floats
            out = [self.project_one(*p) for p in d.tolist()]
            uv = np.array([(self.cx, self.cy) if q is None else q for q in out], float).reshape(-1, 2)
            return uv, np.array([q is not None for q in out], bool)
        u, v, valid = self.project_xyz(d[:, 0], d[:, 1], d[:, 2])
        uv = np.empty((d.shape[0], 2))
        uv[:, 0], uv[:, 1] = u, v
        return uv, valid

    def project_xyz(
        self, x: np.ndarray, y: np.ndarray, z: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project` of directions given by their components (arrays of one shape):
        (u, v, valid), each of that shape."""
        valid = z > 1e-9
        if not valid.all():
            x, y, z = np.where(valid, x, 0.0), np.where(valid, y, 0.0), np.where(valid, z, 1.0)
        xn, yn = x / z, y / z
        r = np.sqrt(xn * xn + yn * yn)
        th = np.arctan(r)
        # theta_d by Horner's rule, in place: within 1e-15 of OpenCV's sum of powers (and
        # its pixels within 1e-12 px) at two thirds of the cost on a pass's ~2500 rays
        k1, k2, k3, k4 = self._k
        t2 = th * th
        td = t2 * k4
        for k in (k3, k2, k1):
            td += k
            td *= t2
        td += 1.0
        td *= th
        cd = np.divide(td, r, out=td, where=r > 1e-8)  # on the axis: theta_d / r is 1
        cd[r <= 1e-8] = 1.0
        xn *= cd  # the distorted point (xd, yd)
        yn *= cd
        u = xn * self.fx if self._alpha == 0.0 else (xn + self._alpha * yn) * self.fx
        u += self.cx
        v = yn * self.fy
        v += self.cy
        return u, v, valid

    def project_cv(self, dirs) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project` through ``cv2.fisheye.projectPoints`` itself (the reference)."""
        d = np.asarray(dirs, np.float64).reshape(-1, 3)
        valid = d[:, 2] > 1e-9
        safe = d if valid.all() else np.where(valid[:, None], d, [0.0, 0.0, 1.0])
        uv, _ = cv2.fisheye.projectPoints(
            np.ascontiguousarray(safe.reshape(-1, 1, 3)),
            _NO_TURN,
            _NO_TURN,
            self.K,
            self.D,
            alpha=self._alpha,  # OpenCV takes the skew here, not from K
        )
        return uv.reshape(-1, 2), valid

    def project_one(self, x: float, y: float, z: float) -> tuple[float, float] | None:
        """:meth:`project` for one direction, in floats (None behind the lens).

        The same operations as OpenCV's ``cv2.fisheye.projectPoints`` (bit for bit)."""
        if not z > 1e-9:
            return None
        xn, yn = x / z, y / z
        r = math.sqrt(xn * xn + yn * yn)
        td = self._theta_d_cv(math.atan(r))
        cd = td * (1.0 / r) if r > 1e-8 else 1.0
        xd, yd = xn * cd, yn * cd
        return (xd + self._alpha * yd) * self.fx + self.cx, yd * self.fy + self.cy

    def project_one_moving(
        self, p: tuple[float, float, float], d1: tuple[float, float, float], d2: tuple[float, float, float]
    ) -> tuple[tuple[float, float], tuple[tuple[float, float], tuple[float, float]]] | None:
        """:meth:`project_one` of the direction ``p`` and the image's motion (px per unit
        motion of the direction, to first order) along ``d1`` and along ``d2``: the
        projection's derivative, in floats (None behind the lens)."""
        x, y, z = p
        if not z > 1e-9:
            return None
        xn, yn = x / z, y / z  # as project_one, operation for operation
        r2 = xn * xn + yn * yn
        r = math.sqrt(r2)
        th = math.atan(r)
        td = self._theta_d_cv(th)
        cd = td * (1.0 / r) if r > 1e-8 else 1.0
        xd, yd = xn * cd, yn * cd
        uv = ((xd + self._alpha * yd) * self.fx + self.cx, yd * self.fy + self.cy)
        k1, k2, k3, k4 = self._k
        t2 = th * th
        if r > 1e-8:
            slope = (1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))) / (1.0 + r2)
        else:  # on the axis the distortion's scale is 1 and flat
            slope = 1.0
        moves = []
        for dx, dy, dz in (d1, d2):
            dxn, dyn = (dx - xn * dz) / z, (dy - yn * dz) / z
            if r > 1e-8:
                dr = (xn * dxn + yn * dyn) / r
                dcd = (slope * dr - cd * dr) / r
            else:
                dcd = 0.0
            dxd, dyd = dxn * cd + xn * dcd, dyn * cd + yn * dcd
            moves.append(((dxd + self._alpha * dyd) * self.fx, dyd * self.fy))
        return uv, (moves[0], moves[1])

    def _theta_d_cv(self, th):
        """``theta_d`` of ``th`` (float or array) as ``cv2.fisheye.projectPoints`` sums it."""
        k1, k2, k3, k4 = self._k
        t2 = th * th
        t3, t4 = t2 * th, t2 * t2
        t5, t6 = t4 * th, t3 * t3
        t8 = t4 * t4
        return th + k1 * t3 + k2 * t5 + k3 * (t6 * th) + k4 * (t8 * th)

    # -- scale -----------------------------------------------------------------------------
    def deg_per_px(self, u: float, v: float) -> float:
        """Local scale (deg per pixel, the geometric mean of the radial and tangential ones)
        at pixel (u, v)."""
        (left, ok_l), (right, ok_r), (top, ok_t), (bottom, ok_b) = (
            self._ray(u - 0.5, v),
            self._ray(u + 0.5, v),
            self._ray(u, v - 0.5),
            self._ray(u, v + 0.5),
        )
        if not (ok_l and ok_r and ok_t and ok_b):
            return math.degrees(1.0 / self._f)
        ux, uy, uz = right[0] - left[0], right[1] - left[1], right[2] - left[2]
        vx, vy, vz = bottom[0] - top[0], bottom[1] - top[1], bottom[2] - top[2]
        area = math.hypot(uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx)  # |du x dv|
        return math.degrees(math.sqrt(max(area, 1e-18)))

    def circle_radius_px(self, theta_deg: float) -> float:
        """Radius (px, along x) of the circle of off-axis angle ``theta_deg`` (< 90)."""
        th = math.radians(min(theta_deg, 89.9))
        pt = np.array([[[math.tan(th), 0.0]]])
        uv = cv2.fisheye.distortPoints(pt, self.K, self.D).reshape(2)
        return float(uv[0] - self.cx)


def theta_d(theta, k):
    """The Kannala-Brandt distorted radius (normalised) of rays ``theta`` (rad, float or
    array) off the axis; ``k`` = (k1, k2, k3, k4)."""
    t2 = theta * theta
    return theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def dtheta_d(theta, k):
    """d theta_d / d theta."""
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])))


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (deg) between unit vectors ``a`` and ``b`` (robust near 0)."""
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))
