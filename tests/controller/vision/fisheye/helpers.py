"""Small sky-camera scenes and their bundles for the fisheye tests."""

from __future__ import annotations

import math
from datetime import UTC, datetime

import numpy as np

from controller.calibration.camera import CameraCal
from controller.calibration.fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3
from controller.vision.fisheye.glare import GlareFit
from hil.skycam import sky_profile


def utc(*a) -> float:
    return datetime(*a, tzinfo=UTC).timestamp()


def small_scene(noise: bool = False, scale: float = 0.5, **kw):
    """The seed camera at ``scale`` times its pixels per side."""
    scn = sky_profile("seed", noise=noise)
    return scn.with_(lens=scn.lens.scaled(scale, "small"), **kw)


def truth_bundle(scn, *, orientation: bool = True, site: bool = True, mask=None) -> FisheyeBundle:
    L = scn.lens
    cam = CameraCal(
        width=L.width, height=L.height, fx=L.fx, fy=L.fy, cx=L.cx, cy=L.cy, dist=tuple(L.D), model="fisheye"
    )
    s = scn.site
    return FisheyeBundle(
        camera=cam,
        orientation=OrientationCal(enu_from_camera=as_mat3(scn.R_enu_from_cam)) if orientation else None,
        site=SiteCal(latitude=s.latitude, longitude=s.longitude, altitude=s.altitude) if site else None,
        mask=mask,
    )


RHO = math.radians(5.0)  # the rim's radius
A = np.array([0.0, 0.0, 1.0])  # the reading's axis
E1, E2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def product_sky(
    eps: tuple[float, float],
    el_deg: float = 30.0,
    seed: int = 0,
    additive: bool = False,
    gradation_ab: tuple[float, float] = (2.0, -0.3),
    rho: float = RHO,
):
    """Rings 1.15-3.2 rim radii (``rho``, rad) about ``A`` of a sky whose light is a
    circumsolar indicatrix times a gradation ``1 + a exp(b / cos Z)`` (``gradation_ab``; or,
    ``additive``, the two summed), the sun ``eps`` (rad, along E1, E2) off the axis; the
    zenith towards E2 at ``el_deg`` of the axis's elevation."""
    rng = np.random.default_rng(seed)
    phi = np.arange(36) * (2 * math.pi / 36)
    chi = np.arange(1.15 * rho, 3.2 * rho + 1e-9, 0.05 * rho)
    e = math.radians(el_deg)
    up = math.sin(e) * A + math.cos(e) * E2
    sun = A + eps[0] * E1 + eps[1] * E2
    sun /= np.linalg.norm(sun)
    dirs = np.cos(phi)[:, None] * E1 + np.sin(phi)[:, None] * E2
    d = np.cos(chi)[None, :, None] * A + np.sin(chi)[None, :, None] * dirs[:, None, :]
    gamma = np.arccos(np.clip(d @ sun, -1, 1))
    cos_z = np.clip(d @ up, 1e-3, 1.0)
    indicatrix = 1.0 + 40.0 * (gamma / rho) ** -2.2
    gradation = 1.0 + gradation_ab[0] * np.exp(gradation_ab[1] / cos_z)
    light = indicatrix + 10.0 * gradation if additive else indicatrix * gradation
    vals = 30.0 * light * (1.0 + rng.normal(0.0, 0.002, light.shape))
    x = (np.arcsin(d @ up) - math.asin(float(A @ up))) / rho
    return vals, chi, phi, up, x


def angle_deg(a, b) -> float:
    """The angle between two directions (deg; not necessarily unit vectors)."""
    return math.degrees(math.acos(min(1.0, float(a @ b) / float(np.linalg.norm(a) * np.linalg.norm(b)))))


def glare_fit(axis=(0.0, 0.0, 1.0), **kw) -> GlareFit:
    """A clean, whole glare rim 3 deg in radius around ``axis`` (camera frame), ``kw`` changed."""
    args = dict(
        axis=np.asarray(axis, float) / np.linalg.norm(axis),
        radius_deg=3.0,
        rms_deg=0.0,
        n_rays=96,
        n_valid=96,
        n_inliers=96,
        max_gap_deg=4.0,
        centre_uv=(160.0, 120.0),
        radius_px=8.0,
        peak=255.0,
        background=100.0,
        core_fill=1.0,
        deg_per_px=0.4,
    )
    return GlareFit(**{**args, **kw})
