"""Small sky-camera scenes and their bundles for the fisheye tests."""

from __future__ import annotations

from datetime import UTC, datetime

from controller.calibration.camera import CameraCal
from controller.calibration.fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3
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
