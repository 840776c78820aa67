"""The HIL scene of the convex-surface sun sensor: a dark glossy hemisphere on a flat base
with ArUco markers, filmed by a fixed camera, lit by the sun (pvlib SPA) and the sky.

Frames
------
* ``model``: the globe's own frame (metres); the globe's centre is the origin, the base's top
  face is ``z = 0`` and the hemisphere is ``z >= 0``.  This is the frame of the "3-D model".
* ``enu``: topocentric East-North-Up.  ``v_enu = R_model_to_enu @ v_model``; the rotation is
  a yaw about the vertical (the installer put the base down at an arbitrary heading) followed
  by a small tilt (the base is not perfectly level).
* camera: OpenCV, ``X_cam = R X_model + t``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import cv2
import numpy as np
import pandas as pd
import pvlib

from ..errors import HilError
from .camera import CameraModel, Pose, azel_to_enu, rot_axis

ARUCO_DICT = cv2.aruco.DICT_4X4_50


@dataclass(frozen=True)
class Globe:
    """The convex surface: hemisphere of ``radius`` (m) with optional low-order bumps."""

    radius: float = 0.20
    bump_amplitude_m: float = 0.0  # peak-ish height of the low-order bumps (about 1 mm real)
    bump_seed: int = 7
    albedo: float = 0.04  # black paint
    roughness: float = 0.04  # GGX alpha
    f0: float = 0.04  # Fresnel reflectance at normal incidence (n = 1.5)

    @cached_property
    def _bumps(self):
        rng = np.random.default_rng(self.bump_seed)
        k = 8
        dirs = rng.normal(size=(k, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        amps = rng.uniform(-1.0, 1.0, k)
        kappa = 3.0  # broad bumps, ~40 deg wide: low order
        return dirs, amps, kappa

    def height(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Radial bump height h(u) (m) and its 3-D gradient for unit directions u (...,3)."""
        if self.bump_amplitude_m == 0.0:
            return np.zeros(u.shape[:-1]), np.zeros_like(u)
        dirs, amps, kappa = self._bumps
        e = np.exp(kappa * (u @ dirs.T - 1.0)) * amps  # (...,k)
        scale = self.bump_amplitude_m
        h = scale * e.sum(-1)
        grad = scale * kappa * (e @ dirs)
        return h, grad

    def surface_points(self, n_points: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """Points (and true normals) spread uniformly over the real hemisphere (model frame)."""
        u = rng.normal(size=(n_points, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        u[:, 2] = np.abs(u[:, 2])
        h, g = self.height(u)
        r = self.radius + h
        p = u * r[:, None]
        n = self.normal(u, r, g)
        return p, n

    @staticmethod
    def normal(u, r, grad) -> np.ndarray:
        gt = grad - np.sum(grad * u, axis=-1, keepdims=True) * u
        n = u - gt / r[..., None]
        return n / np.linalg.norm(n, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Marker:
    id: int
    corners: np.ndarray  # (4,3) model frame, ArUco order: TL, TR, BR, BL as printed


@dataclass(frozen=True)
class Base:
    """Square base plate (top face z = 0) with ArUco markers on a ring around the globe."""

    half_size: float = 0.42
    albedo: float = 0.30
    marker_size: float = 0.07
    ring_radius: float = 0.31
    n_markers: int = 12
    texture_res: float = 0.0005  # m per texel

    @cached_property
    def markers(self) -> tuple[Marker, ...]:
        out = []
        s = self.marker_size
        for k in range(self.n_markers):
            a = 2 * np.pi * (k + 0.5) / self.n_markers
            cx, cy = self.ring_radius * np.cos(a), self.ring_radius * np.sin(a)
            res = self.texture_res  # corners on texel boundaries: the printed marker is exact
            x0 = round((cx - s / 2 + self.half_size) / res) * res - self.half_size
            y0 = round((cy - s / 2 + self.half_size) / res) * res - self.half_size
            corners = np.array([[x0, y0 + s, 0], [x0 + s, y0 + s, 0], [x0 + s, y0, 0], [x0, y0, 0]])
            out.append(Marker(id=k, corners=corners))
        return tuple(out)

    @cached_property
    def texture(self) -> np.ndarray:
        """Albedo texture (float32), row 0 at y = +half_size, column 0 at x = -half_size."""
        n = int(round(2 * self.half_size / self.texture_res))
        tex = np.full((n, n), self.albedo, np.float32)
        dic = cv2.aruco.getPredefinedDictionary(ARUCO_DICT)
        for m in self.markers:
            px = int(round(self.marker_size / self.texture_res))
            img = cv2.aruco.generateImageMarker(dic, m.id, px).astype(np.float32) / 255.0
            img = 0.05 + 0.80 * img  # black ink 0.05, white paper 0.85
            c0, r0 = self._texel(m.corners[0, 0], m.corners[0, 1])
            q = px // 6  # white quiet zone of one cell
            tex[r0 - q : r0 + px + q, c0 - q : c0 + px + q] = 0.85
            tex[r0 : r0 + px, c0 : c0 + px] = img
        return tex

    def _texel(self, x, y) -> tuple[int, int]:
        c = int(round((x + self.half_size) / self.texture_res))
        r = int(round((self.half_size - y) / self.texture_res))
        return c, r

    def marker_table(self) -> list[tuple[int, int, float, float, float]]:
        """Survey of the markers: (id, corner 0..3, x, y, z) in the model frame."""
        out: list[tuple[int, int, float, float, float]] = []
        for m in self.markers:
            for k in range(4):
                x, y, z = (float(v) for v in m.corners[k])
                out.append((m.id, k, x, y, z))
        return out


@dataclass(frozen=True)
class Sensor:
    """Radiometry and noise of the camera."""

    full_scale_radiance: float = 600.0  # W m-2 sr-1 that maps to grey 255 (the exposure)
    full_well_e: float = 8000.0  # electrons at full scale
    read_noise_e: float = 6.0
    noise: bool = True
    jpeg_quality: int | None = None


@dataclass(frozen=True)
class Site:
    latitude: float = 32.4835  # Andimeshk, the paper's site
    longitude: float = 48.3364
    altitude: float = 150.0


@dataclass(frozen=True)
class Scenario:
    """Everything the world needs to render a frame of the hotspot sensor at time t."""

    name: str
    camera: CameraModel
    camera_distance: float  # m, camera centre to globe centre
    camera_elevation_deg: float  # above the model's base plane
    camera_azimuth_enu_deg: float = 180.0  # camera stands to the south, sun behind it
    look_at_z: float = 0.06
    site: Site = field(default_factory=Site)
    globe: Globe = field(default_factory=Globe)
    base: Base = field(default_factory=Base)
    sensor: Sensor = field(default_factory=Sensor)
    yaw_deg: float = 23.0  # model x axis azimuth offset from east (installation heading)
    tilt_deg: float = 0.0  # base not level
    tilt_azimuth_deg: float = 40.0
    pose_jitter_deg: float = 0.0
    pose_jitter_m: float = 0.0
    sun_samples: int = 7  # directions over the 0.53 deg disk

    # --- frames -----------------------------------------------------------------------
    @cached_property
    def R_model_to_enu(self) -> np.ndarray:
        Rz = rot_axis([0, 0, 1], np.radians(self.yaw_deg))
        if self.tilt_deg == 0:
            return Rz
        a = np.radians(self.tilt_azimuth_deg)
        horiz_axis = np.array([np.cos(a), -np.sin(a), 0.0])  # perpendicular to tilt direction
        return rot_axis(horiz_axis, np.radians(self.tilt_deg)) @ Rz

    @property
    def zenith_model(self) -> np.ndarray:
        return self.R_model_to_enu.T @ np.array([0.0, 0.0, 1.0])

    @cached_property
    def pose(self) -> Pose:
        """Nominal camera pose (model -> camera)."""
        dir_enu = azel_to_enu(self.camera_azimuth_enu_deg, self.camera_elevation_deg)
        dir_model = self.R_model_to_enu.T @ dir_enu
        center = dir_model * self.camera_distance
        up_model = self.R_model_to_enu.T @ np.array([0.0, 0.0, 1.0])
        return Pose.look_at(center, [0.0, 0.0, self.look_at_z], up=up_model)

    def with_(self, **kw) -> Scenario:
        return replace(self, **kw)

    # --- truth ------------------------------------------------------------------------
    def sun(self, times) -> dict:
        """Truth from pvlib SPA: azimuth, apparent elevation, ENU and model-frame vectors, and
        clear-sky direct-normal / diffuse irradiance (W m-2)."""
        t = np.atleast_1d(np.asarray(times, dtype=float))
        idx = pd.DatetimeIndex(pd.to_datetime(t, unit="s", utc=True))
        sp = pvlib.solarposition.get_solarposition(
            idx, self.site.latitude, self.site.longitude, altitude=self.site.altitude, method="nrel_numpy"
        )
        az = sp["azimuth"].to_numpy()
        el = sp["apparent_elevation"].to_numpy()
        enu = azel_to_enu(az, el)
        model = enu @ self.R_model_to_enu  # R^T v for row vectors
        zen = np.clip(90.0 - el, 0.0, 90.0)
        am = np.nan_to_num(pvlib.atmosphere.get_relative_airmass(zen, model="kastenyoung1989"), nan=40.0)
        dni = np.where(el > 0, 1361.0 * 0.7 ** (am**0.678), 0.0)
        dhi = np.where(el > 0, 25.0 + 90.0 * np.sqrt(np.clip(np.sin(np.radians(el)), 0, 1)), 5.0)
        return {"azimuth": az, "elevation": el, "enu": enu, "model": model, "dni": dni, "dhi": dhi}


# --- camera profiles ---------------------------------------------------------------------


def seed_camera() -> CameraModel:
    """The paper's camera: 960 x 1080 px, f = 1.135 mm on a 5.37 x 4.04 mm sensor.

    fx = 1.135 / 5.37 * 960, fy = 1.135 / 4.04 * 1080 (the pixels are not square, as the
    paper's sensor size and image size imply).  Distortion: barrel, OpenCV parameters of the
    same sign and rough size as the paper's Australis correction near the globe.
    """
    return CameraModel(
        width=960,
        height=1080,
        fx=1.135 / 5.37 * 960,
        fy=1.135 / 4.04 * 1080,
        cx=480.0,
        cy=540.6,
        dist=(-0.28, 0.06, -7.0e-4, 5.7e-3, 0.0),
        name="seed",
    )


def recommended_camera() -> CameraModel:
    """1280 x 1024 global-shutter machine-vision camera (4.8 um pixels) with a ~7 mm lens."""
    return CameraModel(
        width=1280,
        height=1024,
        fx=1450.0,
        fy=1450.0,
        cx=641.3,
        cy=509.2,
        dist=(-0.09, 0.06, 2.0e-4, -3.0e-4, 0.0),
        name="recommended",
    )


PROFILES = ("seed", "recommended")


def profile(name: str, *, noise: bool = True, **overrides) -> Scenario:
    """A shipped scenario for camera profile ``seed`` or ``recommended``.

    ``noise=True`` is the realistic sensor (shot + read noise; the seed camera also streams
    JPEG); ``noise=False`` is the ideal camera (no noise, no JPEG, still 8-bit).
    """
    if name == "seed":
        sensor = Sensor(
            full_scale_radiance=600.0,
            full_well_e=4000.0,
            read_noise_e=5.0,
            noise=noise,
            jpeg_quality=90 if noise else None,
        )
        scn = Scenario(
            name="seed",
            camera=seed_camera(),
            camera_distance=0.45,
            camera_elevation_deg=40.0,
            sensor=sensor,
            base=Base(marker_size=0.08, ring_radius=0.31),
        )
    elif name == "recommended":
        sensor = Sensor(
            full_scale_radiance=600.0, full_well_e=10000.0, read_noise_e=7.0, noise=noise, jpeg_quality=None
        )
        scn = Scenario(
            name="recommended",
            camera=recommended_camera(),
            camera_distance=0.80,
            camera_elevation_deg=50.0,
            sensor=sensor,
            base=Base(marker_size=0.055, ring_radius=0.285),
        )
    else:
        raise HilError(f"unknown camera profile {name!r}; expected one of {', '.join(PROFILES)}")
    return replace(scn, **overrides) if overrides else scn
