"""The calibrated fisheye lens, pixel <-> direction, through OpenCV's ``cv2.fisheye``.

Camera frame: OpenCV's (x right, y down, z along the optical axis).  Directions are unit
vectors; the off-axis angle is ``theta = arccos(z)``.

OpenCV's fisheye functions go through the pinhole coordinates ``tan(theta) (cos phi, sin
phi)``, so they fold rays beyond 90 deg: ``projectPoints`` is used only in front of the lens
(z > 0), and ``undistortPoints`` returns the mirrored point for theta > 90 deg, which
:meth:`FisheyeLens.rays` detects (the result points away from the pixel's own azimuth about
the principal point) and unfolds.  The unfolded rays agree with the Kannala-Brandt model to
about 95 deg, enough for the horizon of a slightly tilted zenith camera.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-13)

#: Rays beyond this off-axis angle (deg) are not trusted (see the module's docstring).
THETA_LIMIT_DEG = 95.0


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
        p = np.ascontiguousarray(np.asarray(uv, np.float64).reshape(-1, 1, 2))
        n = p.shape[0]
        if n == 0:
            return np.zeros((0, 3)), np.zeros(0, bool)
        xy = cv2.fisheye.undistortPoints(p, self.K, self.D, criteria=_CRIT).reshape(-1, 2)
        a = (p[:, 0, 0] - self.cx) / self.fx
        b = (p[:, 0, 1] - self.cy) / self.fy
        r_pix = np.hypot(a, b)
        r_und = np.hypot(xy[:, 0], xy[:, 1])
        folded = (xy[:, 0] * a + xy[:, 1] * b) < 0
        theta = np.where(folded, np.pi - np.arctan(r_und), np.arctan(r_und))
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(r_pix > 0, a / r_pix, 1.0)
            s = np.where(r_pix > 0, b / r_pix, 0.0)
        st = np.sin(theta)
        d = np.stack([st * c, st * s, np.cos(theta)], axis=1)
        valid = np.isfinite(d).all(axis=1) & (theta <= math.radians(THETA_LIMIT_DEG))
        return np.where(valid[:, None], d, np.nan), valid

    def ray(self, u: float, v: float) -> np.ndarray:
        d, _ = self.rays([[u, v]])
        return d[0]

    # -- direction -> pixel --------------------------------------------------------------
    def project(self, dirs) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame directions (N, 3) -> pixels (N, 2); ``valid`` only in front (z > 0)."""
        d = np.asarray(dirs, np.float64).reshape(-1, 3)
        valid = d[:, 2] > 1e-9
        safe = np.where(valid[:, None], d, [0.0, 0.0, 1.0])
        uv, _ = cv2.fisheye.projectPoints(
            np.ascontiguousarray(safe.reshape(-1, 1, 3)), np.zeros(3), np.zeros(3), self.K, self.D
        )
        return uv.reshape(-1, 2), valid

    # -- scale -----------------------------------------------------------------------------
    def deg_per_px(self, u: float, v: float) -> float:
        """Local scale (deg per pixel, the geometric mean of the radial and tangential ones)
        at pixel (u, v)."""
        d, ok = self.rays([[u - 0.5, v], [u + 0.5, v], [u, v - 0.5], [u, v + 0.5]])
        if not ok.all():
            return math.degrees(1.0 / self._f)
        du = d[1] - d[0]
        dv = d[3] - d[2]
        area = float(np.linalg.norm(np.cross(du, dv)))
        return math.degrees(math.sqrt(max(area, 1e-18)))

    def circle_radius_px(self, theta_deg: float) -> float:
        """Radius (px, along x) of the circle of off-axis angle ``theta_deg`` (< 90)."""
        th = math.radians(min(theta_deg, 89.9))
        pt = np.array([[[math.tan(th), 0.0]]])
        uv = cv2.fisheye.distortPoints(pt, self.K, self.D).reshape(2)
        return float(uv[0] - self.cx)


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (deg) between unit vectors ``a`` and ``b`` (robust near 0)."""
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))
