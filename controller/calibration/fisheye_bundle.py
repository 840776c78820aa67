"""The fisheye sky camera's calibration bundle: one TOML file, the hotspot bundle's style.

```toml
mask = "mask.png"           # optional (white = use); relative to this file's folder

[camera]
model = "fisheye"           # OpenCV cv2.fisheye (Kannala-Brandt)
width = 640
height = 480
fx = 166.0
fy = 166.0
cx = 319.5
cy = 239.5
dist = [k1, k2, k3, k4]     # cv2.fisheye D
rms_px = 0.06               # optional: reprojection RMS of the lens calibration

[orientation]               # optional: without it, directions are in the camera frame
enu_from_camera = [[..], [..], [..]]   # 3 x 3; columns = camera x, y, z (OpenCV) in ENU
residual_deg = 0.02         # optional: RMS residual of the fit that produced it
method = "sun"              # optional: how it was obtained

[site]                      # optional: enables the ephemeris gate
latitude = 32.4835          # deg, north positive
longitude = 48.3364         # deg, east positive
altitude = 150.0            # m
```

``d_enu = enu_from_camera @ d_cam``; the pose's rotation in ``X_cam = R X_world + t`` is its
transpose.  Read with the project's one schema (:mod:`controller.schema`): unknown keys are
errors, and every error names the file, the key and what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write
from ..errors import ConfigError
from ..schema import Where, internal, load, load_file, setting
from .camera import CameraCal

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]

#: How far from a rotation an ``enu_from_camera`` may be (max |R^T R - I| entry) before it
#: is refused; smaller deviations (rounding in a hand-edited file) are re-orthonormalised.
ORTHONORMAL_TOL = 1e-3


@dataclass(frozen=True, kw_only=True)
class OrientationCal:
    """The camera's rotation to ENU."""

    enu_from_camera: Mat3 = setting(
        doc="3 x 3 rotation whose columns are the camera's x, y, z axes (OpenCV) in ENU: d_enu = M d_cam."
    )
    residual_deg: float | None = setting(
        None, doc="RMS residual of the fit that produced it.", unit="deg", ge=0
    )
    method: str | None = setting(None, doc='How it was obtained ("sun", "sun+horizon", "survey").')
    frames: int | None = setting(None, doc="Number of detections used.", ge=0)

    def __schema_check__(self, at: Where) -> OrientationCal:
        M = np.asarray(self.enu_from_camera, float)
        dev = float(np.abs(M.T @ M - np.eye(3)).max())
        if dev > ORTHONORMAL_TOL or np.linalg.det(M) <= 0:
            raise at.child("enu_from_camera").error(
                f"a rotation matrix (orthonormal within {ORTHONORMAL_TOL}, determinant +1)",
                [list(r) for r in self.enu_from_camera],
            )
        return replace(self, enu_from_camera=as_mat3(nearest_rotation(M)))

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.enu_from_camera, float)


@dataclass(frozen=True, kw_only=True)
class SiteCal:
    """Where the camera stands (for the ephemeris gate and the orientation fit)."""

    latitude: float = setting(doc="Latitude, north positive.", unit="deg", ge=-90, le=90)
    longitude: float = setting(doc="Longitude, east positive.", unit="deg", ge=-180, le=180)
    altitude: float = setting(0.0, doc="Altitude above sea level.", unit="m", ge=-500, le=9000)


@dataclass(frozen=True, kw_only=True)
class FisheyeBundle:
    """The fisheye sky camera's calibration bundle."""

    camera: CameraCal = setting(doc='Lens intrinsics; model = "fisheye" (cv2.fisheye).')
    orientation: OrientationCal | None = setting(None, doc="Rotation to ENU.")
    site: SiteCal | None = setting(None, doc="Site of the camera.")
    mask: Path | None = setting(None, doc="Mask image of the camera's size (white = use).", path="file")
    notes: dict[str, Any] = setting(
        default_factory=dict, doc="Free-form notes of the calibration run (ignored)."
    )
    path: Path | None = internal(None)

    def __schema_check__(self, at: Where) -> FisheyeBundle:
        if self.camera.model != "fisheye":
            raise at.child("camera").child("model").error('"fisheye" (a cv2.fisheye lens)', self.camera.model)
        return self

    @property
    def enu_from_camera(self) -> np.ndarray | None:
        return self.orientation.matrix if self.orientation is not None else None


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to ``M`` (Frobenius), by SVD."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    return R


def as_mat3(M: np.ndarray) -> Mat3:
    return tuple(tuple(float(x) for x in row) for row in np.asarray(M, float))  # type: ignore[return-value]


def load_fisheye_bundle(path: str | Path) -> FisheyeBundle:
    """Read and validate a bundle; errors name the file, the key and what was expected."""
    return replace(load_file(FisheyeBundle, path), path=Path(path))


def fisheye_bundle_from_dict(doc: dict[str, Any], path: Path | None = None) -> FisheyeBundle:
    """Validate an already parsed bundle (``path``: where relative paths resolve)."""
    return replace(load(FisheyeBundle, doc, str(path) if path is not None else None), path=path)


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (str, Path)):
        s = str(v).replace("\\", "\\\\").replace('"', '\\"')
        return f'"{s}"'
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    raise TypeError(type(v))


def fisheye_bundle_to_toml(b: FisheyeBundle, folder: Path | None = None) -> str:
    """Serialise; the mask's path is written relative to ``folder`` when inside it."""
    out = ["# heliotrack fisheye sky-camera calibration bundle (see docs/fisheye.md)"]
    if b.mask is not None:
        m = Path(b.mask)
        if folder is not None:
            try:
                m = m.resolve().relative_to(Path(folder).resolve())
            except ValueError:
                pass
        out.append(f"mask = {_fmt(m)}")
    c = b.camera
    out += [
        "",
        "[camera]",
        'model = "fisheye"',
        f"width = {c.width}",
        f"height = {c.height}",
        f"fx = {_fmt(c.fx)}",
        f"fy = {_fmt(c.fy)}",
        f"cx = {_fmt(c.cx)}",
        f"cy = {_fmt(c.cy)}",
        f"dist = {_fmt(list(c.dist))}",
    ]
    if c.rms_px is not None:
        out.append(f"rms_px = {_fmt(c.rms_px)}")
    o = b.orientation
    if o is not None:
        out += [
            "",
            "[orientation]",
            "enu_from_camera = [" + ", ".join(_fmt(list(r)) for r in o.enu_from_camera) + "]",
        ]
        if o.residual_deg is not None:
            out.append(f"residual_deg = {_fmt(o.residual_deg)}")
        if o.method is not None:
            out.append(f"method = {_fmt(o.method)}")
        if o.frames is not None:
            out.append(f"frames = {int(o.frames)}")
    if b.site is not None:
        s = b.site
        out += [
            "",
            "[site]",
            f"latitude = {_fmt(s.latitude)}",
            f"longitude = {_fmt(s.longitude)}",
            f"altitude = {_fmt(s.altitude)}",
        ]
    if b.notes:
        out += ["", "[notes]"] + [f"{k} = {_fmt(v)}" for k, v in b.notes.items()]
    return "\n".join(out) + "\n"


def save_fisheye_bundle(b: FisheyeBundle, path: str | Path) -> Path:
    """Write atomically, so a failure loses nothing already stored."""
    path = Path(path)
    return atomic_write(path, fisheye_bundle_to_toml(b, path.parent))


def update_fisheye_bundle(path: str | Path, **changes: Any) -> FisheyeBundle:
    """Load (or start) the bundle at ``path``, replace fields, save; returns the new bundle."""
    path = Path(path)
    if path.exists():
        b = load_fisheye_bundle(path)
    else:
        if "camera" not in changes:
            raise ConfigError(path, "camera", "the lens first (heliotrack calibrate fisheye lens ...)")
        b = FisheyeBundle(camera=changes["camera"], path=path)
    b = replace(b, **changes)
    save_fisheye_bundle(b, path)
    return replace(b, path=path)
