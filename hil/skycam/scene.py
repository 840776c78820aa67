"""What the HIL sky camera looks at: site, lens, orientation, sky, glare, clouds, distractors.

Frames: ENU (x East, y North, z Up) for the world; the camera frame is OpenCV's (x right,
y down, z along the optical axis).  ``enu_from_camera`` is the 3 x 3 rotation whose columns
are the camera's axes in ENU, so ``d_enu = enu_from_camera @ d_cam`` (the pose's ``R`` in
``X_cam = R X_world + t`` is its transpose).  The identity is a camera looking at the zenith
with image x towards East and image y (down the image) towards North.

Truth for the sun is pvlib's SPA (apparent elevation, i.e. with refraction).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd
import pvlib

from ..camera.scene import Site
from ..errors import HilError
from .clouds import CloudField
from .lens import FisheyeLens, hd_lens, seed_lens
from .sky import SkyModel
from .sun import GlareModel

#: Sites used by the benchmark: the hotspot paper's, this paper's, and a southern one.
SITES = {
    "andimeshk": Site(latitude=32.4835, longitude=48.3364, altitude=150.0),
    "fuzhou": Site(latitude=26.0745, longitude=119.2965, altitude=20.0),
    "alice-springs": Site(latitude=-23.6980, longitude=133.8807, altitude=545.0),
}


@dataclass(frozen=True)
class SkySensor:
    """Colour sensor: ``full_well_e`` electrons at full scale, ``read_noise_e``, optional
    JPEG, ``vignetting`` (relative fall-off at the image circle's edge), ``exposure``
    (relative to nominal: > 1 brighter, larger glare).  With ``auto_exposure`` the exposure
    is set per frame so that the 97th percentile of the sky's grey level (20 deg round the
    sun excluded) is
    ``auto_target``; ``exposure`` then multiplies that."""

    full_well_e: float = 6000.0
    read_noise_e: float = 8.0
    noise: bool = True
    jpeg_quality: int | None = None
    vignetting: float = 0.15
    exposure: float = 1.0
    auto_exposure: bool = False
    auto_target: float = 0.70


Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]


def orientation(
    yaw_deg: float = 0.0,
    tilt_deg: float = 0.0,
    tilt_azimuth_deg: float = 0.0,
    look_el_deg: float = 90.0,
    look_az_deg: float = 0.0,
) -> Matrix3:
    """``enu_from_camera`` of a camera looking at elevation ``look_el_deg`` / azimuth
    ``look_az_deg`` (90: the zenith), turned by ``yaw_deg`` about its optical axis (counter-
    clockwise seen from below for a zenith camera), then tipped by ``tilt_deg`` towards
    ``tilt_azimuth_deg`` (installation error)."""

    def rot(axis, ang):
        a = np.asarray(axis, float) / np.linalg.norm(axis)
        K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        return np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K

    R = rot([0, 0, 1], np.radians(yaw_deg))
    if look_el_deg != 90.0:  # tip the zenith camera down to (look_az, look_el)
        a = np.radians(look_az_deg)
        axis = np.array([np.cos(a), -np.sin(a), 0.0])
        R = rot(axis, -np.radians(90.0 - look_el_deg)) @ R
    if tilt_deg:
        a = np.radians(tilt_azimuth_deg)
        axis = np.array([np.cos(a), -np.sin(a), 0.0])  # horizontal, perpendicular to the tilt
        R = rot(axis, -np.radians(tilt_deg)) @ R
    return tuple(tuple(float(x) for x in row) for row in R)  # type: ignore[return-value]


@dataclass(frozen=True)
class SkyScene:
    """Everything needed to render a sky-camera frame at time t."""

    name: str
    lens: FisheyeLens
    enu_from_camera: Matrix3 = field(default_factory=lambda: orientation())
    site: Site = field(default_factory=lambda: SITES["andimeshk"])
    sky: SkyModel = field(default_factory=SkyModel)
    glare: GlareModel = field(default_factory=GlareModel)
    sensor: SkySensor = field(default_factory=SkySensor)
    clouds: CloudField | None = None
    distractors: tuple = ()

    @property
    def R_enu_from_cam(self) -> np.ndarray:
        return np.asarray(self.enu_from_camera, float)

    def with_(self, **kw) -> SkyScene:
        return replace(self, **kw)

    def sun(self, times) -> dict:
        """pvlib SPA truth: ``azimuth`` (deg from N, clockwise), ``elevation`` (apparent,
        deg), ``enu`` unit vectors (N, 3) and ``cam`` (camera frame)."""
        return sun_position(self.site, times, self.R_enu_from_cam)


def sun_position(site: Site, times, enu_from_camera: np.ndarray | None = None) -> dict:
    t = np.atleast_1d(np.asarray(times, dtype=float))
    idx = pd.DatetimeIndex(pd.to_datetime(t, unit="s", utc=True))
    sp = pvlib.solarposition.get_solarposition(
        idx, site.latitude, site.longitude, altitude=site.altitude, method="nrel_numpy"
    )
    az = sp["azimuth"].to_numpy()
    el = sp["apparent_elevation"].to_numpy()
    a, e = np.radians(az), np.radians(el)
    enu = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)
    out = {"azimuth": az, "elevation": el, "enu": enu}
    if enu_from_camera is not None:
        out["cam"] = enu @ np.asarray(enu_from_camera)  # R^T v for row vectors
    return out


PROFILES = ("seed", "hd")


def sky_profile(name: str, *, noise: bool = True, **overrides) -> SkyScene:
    """A shipped sky camera.

    ``seed``: 640 x 480, JPEG q90 (a USB camera as in the paper), sun disk ~400 px.
    ``hd``: 1280 x 960 machine-vision camera, lossless, the same glare in degrees
    (~1600 px).  Both are installed with a small tilt (0.8 deg) and an arbitrary heading.
    ``noise=False`` gives the ideal camera (no noise, no JPEG, still 8-bit).
    """
    if name == "seed":
        lens = seed_lens()
        sensor = SkySensor(
            full_well_e=6000.0, read_noise_e=8.0, noise=noise, jpeg_quality=90 if noise else None
        )
    elif name == "hd":
        lens = hd_lens()
        sensor = SkySensor(full_well_e=10000.0, read_noise_e=6.0, noise=noise, jpeg_quality=None)
    else:
        raise HilError(f"unknown sky-camera profile {name!r}; expected one of {', '.join(PROFILES)}")
    scn = SkyScene(
        name=name,
        lens=lens,
        sensor=sensor,
        enu_from_camera=orientation(yaw_deg=17.0, tilt_deg=0.8, tilt_azimuth_deg=120.0),
    )
    return replace(scn, **overrides) if overrides else scn
