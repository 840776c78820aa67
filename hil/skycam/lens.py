"""Kannala-Brandt fisheye lens of the HIL sky camera, written without OpenCV or the controller.

The model is the one OpenCV's ``cv2.fisheye`` uses (so a bundle can carry the world's K and
D unchanged), but it is implemented here from its definition so that a sign or convention
error on the controller's side cannot cancel the same error in the world:

* a camera-frame direction ``(x, y, z)`` (OpenCV axes: x right, y down, z along the optical
  axis) has the off-axis angle ``theta = atan2(hypot(x, y), z)`` (radians, 0..pi) and the
  azimuth ``phi = atan2(y, x)`` about the axis;
* ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``;
* ``u = fx theta_d cos(phi) + cx``, ``v = fy theta_d sin(phi) + cy`` (pixels, the centre of
  the top-left pixel is (0, 0)).

Unlike OpenCV's ``projectPoints`` (which goes through ``x/z`` and so folds rays beyond
90 deg onto the front hemisphere) this form is valid up to the lens's field of view; rays
beyond ``fov_deg / 2`` do not reach the sensor (the dark outside of the image circle).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..errors import HilError


@dataclass(frozen=True)
class FisheyeLens:
    """Intrinsics of a fisheye camera: OpenCV K (``fx fy cx cy``, px) and D = ``(k1..k4)``.

    ``fov_deg`` is the full field of view of the image circle (deg); rays with an off-axis
    angle above ``fov_deg / 2`` are outside it.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    D: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    fov_deg: float = 190.0
    name: str = "fisheye"

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0 or self.fx <= 0 or self.fy <= 0:
            raise HilError(f"lens {self.name!r}: image size and focal lengths must be positive")
        if not 0.0 < self.fov_deg < 360.0:
            raise HilError(f"lens {self.name!r}: fov_deg must be within (0, 360), got {self.fov_deg}")
        th = np.linspace(0.0, self.theta_max, 512)
        if np.any(np.diff(self.theta_d(th)) <= 0):
            raise HilError(
                f"lens {self.name!r}: theta_d(theta) is not increasing up to "
                f"{self.fov_deg / 2:.1f} deg with D = {self.D}"
            )

    # -- model ------------------------------------------------------------------------
    @property
    def theta_max(self) -> float:
        """Half field of view (rad)."""
        return float(np.radians(self.fov_deg / 2.0))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def theta_d(self, theta):
        """Distorted angle (rad) of the off-axis angle ``theta`` (rad)."""
        t2 = np.asarray(theta, float) ** 2
        k1, k2, k3, k4 = self.D
        return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))

    def _dtheta_d(self, theta):
        t2 = np.asarray(theta, float) ** 2
        k1, k2, k3, k4 = self.D
        return 1.0 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))

    def theta_from_theta_d(self, theta_d) -> tuple[np.ndarray, np.ndarray]:
        """Invert ``theta_d(theta)`` by Newton's method; returns (theta rad, converged)."""
        td = np.asarray(theta_d, float)
        th = np.clip(td, 0.0, self.theta_max * 1.2)
        for _ in range(30):
            step = (self.theta_d(th) - td) / self._dtheta_d(th)
            th = th - step
            if np.all(np.abs(step) < 1e-14):
                break
        ok = np.isfinite(th) & (np.abs(self.theta_d(th) - td) < 1e-9) & (th >= 0)
        return th, ok

    def project(self, dirs_cam) -> tuple[np.ndarray, np.ndarray]:
        """Camera-frame directions (N, 3) -> pixels (N, 2) and ``valid`` (inside the circle)."""
        d = np.asarray(dirs_cam, float).reshape(-1, 3)
        rxy = np.hypot(d[:, 0], d[:, 1])
        theta = np.arctan2(rxy, d[:, 2])
        td = self.theta_d(theta)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(rxy > 0, d[:, 0] / rxy, 1.0)
            s = np.where(rxy > 0, d[:, 1] / rxy, 0.0)
        uv = np.stack([self.fx * td * c + self.cx, self.fy * td * s + self.cy], axis=1)
        return uv, theta <= self.theta_max

    def unproject(self, uv) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (N, 2) -> unit camera-frame directions (N, 3) and ``valid``."""
        p = np.asarray(uv, float).reshape(-1, 2)
        a = (p[:, 0] - self.cx) / self.fx
        b = (p[:, 1] - self.cy) / self.fy
        td = np.hypot(a, b)
        theta, ok = self.theta_from_theta_d(td)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(td > 0, a / td, 1.0)
            s = np.where(td > 0, b / td, 0.0)
        st = np.sin(theta)
        d = np.stack([st * c, st * s, np.cos(theta)], axis=1)
        return d, ok & (theta <= self.theta_max)

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit rays through every pixel centre (H, W, 3) float32 and the image-circle mask."""
        return _rays(self)

    def scaled(self, factor: float, name: str | None = None) -> FisheyeLens:
        """The same lens on a sensor with ``factor`` times the pixels per side."""
        w = round(self.width * factor)
        h = round(self.height * factor)
        return replace(
            self,
            width=w,
            height=h,
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=(self.cx + 0.5) * factor - 0.5,
            cy=(self.cy + 0.5) * factor - 0.5,
            name=name or f"{self.name}x{factor:g}",
        )

    def deg_per_px(self, theta_rad: float = 0.0) -> tuple[float, float]:
        """(radial, tangential) degrees per pixel at off-axis angle ``theta_rad``."""
        f = 0.5 * (self.fx + self.fy)
        radial = 1.0 / (f * float(self._dtheta_d(theta_rad)))
        if theta_rad < 1e-6:
            return np.degrees(radial), np.degrees(radial)
        tang = np.sin(theta_rad) / (f * float(self.theta_d(theta_rad)))
        return float(np.degrees(radial)), float(np.degrees(tang))


@lru_cache(maxsize=6)
def _rays(lens: FisheyeLens) -> tuple[np.ndarray, np.ndarray]:
    v, u = np.mgrid[0 : lens.height, 0 : lens.width].astype(np.float64)
    d, ok = lens.unproject(np.stack([u.ravel(), v.ravel()], axis=1))
    d = d.reshape(lens.height, lens.width, 3).astype(np.float32)
    ok = ok.reshape(lens.height, lens.width)
    d.setflags(write=False)
    ok.setflags(write=False)
    return d, ok


def seed_lens() -> FisheyeLens:
    """The paper's class of camera: 640 x 480, a ~1.6 mm fisheye (190 deg) on a 1/4" sensor.

    Mild barrel Kannala-Brandt terms put the 90-deg circle at ~231 px from the centre, so the
    whole sky fits the 480-px height and a sliver of ground shows beyond the horizon.
    """
    return FisheyeLens(
        width=640,
        height=480,
        fx=166.0,
        fy=166.0,
        cx=319.5,
        cy=239.5,
        D=(-0.0420, 0.0010, -0.0005, 0.0),
        fov_deg=190.0,
        name="seed",
    )


def hd_lens() -> FisheyeLens:
    """1280 x 960 machine-vision sky camera: the seed geometry at twice the pixels per side,
    with a slightly different distortion (another lens of the same class)."""
    base = seed_lens().scaled(2.0, name="hd")
    return replace(base, fx=333.0, fy=332.4, cx=640.3, cy=479.1, D=(-0.0390, 0.0012, -0.0006, 0.0))


def full_hd_lens() -> FisheyeLens:
    """1920 x 1080 (16:9) sensor with the sky circle inside the height (for timing)."""
    return FisheyeLens(
        width=1920,
        height=1080,
        fx=372.0,
        fy=372.0,
        cx=959.5,
        cy=539.5,
        D=(-0.0420, 0.0010, -0.0005, 0.0),
        fov_deg=190.0,
        name="fullhd",
    )
