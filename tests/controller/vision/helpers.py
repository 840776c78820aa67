"""Small renders for fast tests: the recommended geometry scaled down to 320 x 256 px."""

from __future__ import annotations

from datetime import UTC, datetime

from controller.calibration import AzimuthCal, CalibrationBundle, CameraCal, LevelCal, PoseCal, SurfaceCal
from hil.camera import CameraModel, profile


def small_scenario(noise: bool = False, scale: float = 0.25, **kw):
    base = profile("recommended", noise=noise)
    c = base.camera
    cam = CameraModel(
        width=int(c.width * scale),
        height=int(c.height * scale),
        fx=c.fx * scale,
        fy=c.fy * scale,
        cx=(c.cx + 0.5) * scale - 0.5,
        cy=(c.cy + 0.5) * scale - 0.5,
        dist=c.dist,
        name="small",
    )
    return base.with_(camera=cam, **kw)


def truth_bundle(scn, *, level=True, offset=None) -> CalibrationBundle:
    cam = scn.camera
    return CalibrationBundle(
        camera=CameraCal(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, tuple(cam.dist)),
        surface=SurfaceCal(kind="sphere", center=(0.0, 0.0, 0.0), radius=scn.globe.radius),
        pose=PoseCal(rvec=tuple(scn.pose.rvec), tvec=tuple(scn.pose.tvec)),
        level=LevelCal(zenith_model=tuple(scn.zenith_model)) if level else None,
        azimuth=AzimuthCal(offset),
    )


def utc(*a) -> float:
    return datetime(*a, tzinfo=UTC).timestamp()
