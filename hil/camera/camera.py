"""Pinhole + Brown-Conrady camera of the HIL world (OpenCV conventions).

The world side keeps its own small geometry helpers on purpose: the HIL must never import
the controller, so that a sign error in one cannot cancel the same error in the other.
OpenCV is used for the distortion model (it is the reference implementation of it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics: ``width height fx fy cx cy`` (px) and ``dist = (k1, k2, p1, p2, k3)``."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    name: str = "camera"

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=float)

    def project(self, pts_world, rvec, tvec) -> np.ndarray:
        """World points (N,3) -> distorted pixel coordinates (N,2)."""
        pts = np.ascontiguousarray(np.asarray(pts_world, dtype=np.float64).reshape(-1, 1, 3))
        uv, _ = cv2.projectPoints(
            pts, np.asarray(rvec, float), np.asarray(tvec, float), self.K, self.dist_array
        )
        return uv.reshape(-1, 2)

    def ray_dirs(self) -> np.ndarray:
        """Unit ray directions in the camera frame for every pixel centre, (H, W, 3)."""
        return _ray_dirs(self)

    def rays_at(self, uv) -> np.ndarray:
        """Unit camera-frame rays through distorted pixel positions (N,2) -> (N,3)."""
        return _undistort_rays(self, np.asarray(uv, float).reshape(-1, 2))


def _undistort_rays(cam: CameraModel, uv: np.ndarray) -> np.ndarray:
    pts = np.ascontiguousarray(uv.reshape(-1, 1, 2))
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    xy = cv2.undistortPoints(pts, cam.K, cam.dist_array, None, None, None, crit).reshape(-1, 2)
    d = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@lru_cache(maxsize=8)
def _ray_dirs(cam: CameraModel) -> np.ndarray:
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float64)
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    d = _undistort_rays(cam, uv)
    out = d.reshape(cam.height, cam.width, 3)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class Pose:
    """Exterior orientation, OpenCV: ``X_cam = R X_world + t`` (world = the globe's model frame)."""

    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def rvec(self) -> np.ndarray:
        return cv2.Rodrigues(np.asarray(self.R, float))[0].ravel()

    @property
    def tvec(self) -> np.ndarray:
        return np.asarray(self.t, float).ravel()

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return -np.asarray(self.R).T @ np.asarray(self.t)

    @staticmethod
    def look_at(center, target, up=(0.0, 0.0, 1.0)) -> Pose:
        """Camera at ``center`` looking at ``target``; image 'up' towards world ``up``."""
        c = np.asarray(center, float)
        z = np.asarray(target, float) - c
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, float))
        if np.linalg.norm(x) < 1e-9:
            x = np.cross(z, [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.stack([x, y, z])  # rows: camera axes in world coordinates
        return Pose(R=R, t=-R @ c)

    def perturbed(self, rng: np.random.Generator, rot_deg: float, trans_m: float) -> Pose:
        """Small random rotation about the camera centre and shift (pose jitter)."""
        if rot_deg <= 0 and trans_m <= 0:
            return self
        w = rng.normal(0.0, np.radians(rot_deg), 3)
        dR = cv2.Rodrigues(w)[0]
        R = dR @ np.asarray(self.R)
        c = self.center + rng.normal(0.0, trans_m, 3)
        return Pose(R=R, t=-R @ c)


def rot_axis(axis, angle_rad) -> np.ndarray:
    """Rotation matrix about a unit axis (right-handed)."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    return cv2.Rodrigues(a * float(angle_rad))[0]


def azel_to_enu(az_deg, el_deg) -> np.ndarray:
    """Azimuth clockwise from north, elevation (deg) -> ENU unit vector(s). World-side copy."""
    az = np.radians(np.asarray(az_deg, float))
    el = np.radians(np.asarray(el_deg, float))
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)
