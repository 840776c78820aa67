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
sky_scale = 1.0             # optional: the sky model's correction of the rim times this
sky_calibration = [k0, k1, k0, k1]   # optional: per sky model (dipole, by elevation), the
                            # correction times k0 + k1 (1 / sin(el) - 1), the column smear off

[radiometry]                # optional: grey level <-> light (docs/fisheye.md, "Radiometry")
response = "srgb"           # "linear" (default), "srgb", "gamma" (with gamma = ..) or "table"
table = [..]                # with response = "table": 256 values, light at each grey level
vignetting = [c1, c2, c3]   # relative illumination 1 + c1 t^2 + c2 t^4 + c3 t^6 (t: field angle, rad)

[site]                      # optional: enables the ephemeris gate
latitude = 32.4835          # deg, north positive
longitude = 48.3364         # deg, east positive
altitude = 150.0            # m

[mount]                     # optional, a panel camera's: how it sits on its panel
panel_from_camera = [[..], [..], [..]]   # 3 x 3; columns = camera x, y, z in the panel's frame
residual_deg = 0.02         # optional: RMS residual of the fit (heliotrack calibrate fisheye mount)
```

``d_enu = enu_from_camera @ d_cam``; a panel camera's ``d_panel = panel_from_camera @ d_cam``,
the panel's frame being that of a camera mounted exactly (z the panel's normal, x towards
increasing azimuth or rotation: :mod:`controller.closedloop.geometry`).  The pose's
rotation in ``X_cam = R X_world + t`` is ``enu_from_camera``'s transpose.  Read with the project's one schema (:mod:`controller.schema`): unknown keys are
errors, and every error names the file, the key and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..errors import ConfigError
from ..schema import Where, internal, load, load_file, setting
from .camera import CameraCal
from .checked_write import write_if_valid
from .toml_write import camera_section, notes_section, relative_path, toml_value

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
    sky_scale: float = setting(
        1.0,
        doc="The sky model's correction of the glare's rim times this (fitted with the rotation "
        "from a day of sun detections; 1: the model as it is).",
        ge=0.25,
        le=4.0,
    )
    sky_calibration: tuple[float, float, float, float] | None = setting(
        None,
        doc="Per camera, in place of sky_scale: (k0, k1) of the sky's dipole, then (k0, k1) of its "
        "model by elevation; the model's correction of the rim times k0 + k1 (1 / sin(el) - 1), "
        "with a frame-transfer column smear taken off the frames (fitted with the rotation from a "
        "day of sun detections; absent: sky_scale alone, as before).",
    )
    locator: Literal["rim", "rings"] | None = setting(
        None,
        doc="With the site known, what places the sun from the first frame on, as the calibration "
        'day chose (heliotrack calibrate fisheye orientation): "rim", the glare\'s rim, or "rings", '
        "the sky's rings around it (a sky whose light is a product of the angle to the sun and the "
        "elevation); the choice is still learned from the ephemeris as frames come (absent: "
        "learned only).",
    )

    def __schema_check__(self, at: Where) -> OrientationCal:
        return replace(
            self, enu_from_camera=_checked_rotation(self.enu_from_camera, at.child("enu_from_camera"))
        )

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.enu_from_camera, float)


def _checked_rotation(M: Mat3, at: Where) -> Mat3:
    """``M`` made exactly a rotation, or an error at ``at`` when it is not near one."""
    A = np.asarray(M, float)
    dev = float(np.abs(A.T @ A - np.eye(3)).max())
    if dev > ORTHONORMAL_TOL or np.linalg.det(A) <= 0:
        raise at.error(
            f"a rotation matrix (orthonormal within {ORTHONORMAL_TOL}, determinant +1)", [list(r) for r in M]
        )
    return as_mat3(nearest_rotation(A))


@dataclass(frozen=True, kw_only=True)
class MountCal:
    """A panel camera's rotation on its panel (the panel-mounted closed loop)."""

    panel_from_camera: Mat3 = setting(
        doc="3 x 3 rotation whose columns are the camera's x, y, z axes (OpenCV) in the panel's "
        "frame (z the panel's normal, x towards increasing azimuth or rotation, y = z x x): "
        "d_panel = M d_cam.  The identity: a camera whose axis is the panel's normal."
    )
    residual_deg: float | None = setting(
        None, doc="RMS residual of the fit that produced it.", unit="deg", ge=0
    )
    method: str | None = setting(None, doc='How it was obtained ("sun+panel angles", "jig").')
    frames: int | None = setting(None, doc="Number of sightings used.", ge=0)

    def __schema_check__(self, at: Where) -> MountCal:
        return replace(
            self, panel_from_camera=_checked_rotation(self.panel_from_camera, at.child("panel_from_camera"))
        )

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.panel_from_camera, float)


@dataclass(frozen=True, kw_only=True)
class SiteCal:
    """Where the camera stands (for the ephemeris gate and the orientation fit)."""

    latitude: float = setting(doc="Latitude, north positive.", unit="deg", ge=-90, le=90)
    longitude: float = setting(doc="Longitude, east positive.", unit="deg", ge=-180, le=180)
    altitude: float = setting(0.0, doc="Altitude above sea level.", unit="m", ge=-500, le=9000)


#: Field angles (deg) over which a declared vignetting must stay a plausible illumination.
VIGNETTING_CHECK_DEG = 100.0
#: The least relative illumination a declared vignetting may reach there.
VIGNETTING_MIN = 0.05


@dataclass(frozen=True, kw_only=True)
class RadiometryCal:
    """How the frame's grey levels relate to the light that made them.

    The sky's brightness next to the glare is measured a few radii out and removed at the
    rim, where the grey level is far higher; on a camera whose output is not linear in light
    (sRGB JPEGs) or whose lens darkens towards the edge of the field, that transfer needs
    the response and the vignetting.  Without this section the frame is taken as linear and
    evenly lit (as the HIL renders it).
    """

    response: Literal["linear", "srgb", "gamma", "table"] = setting(
        "linear",
        doc='Grey level to light: "linear", "srgb" (IEC 61966-2-1), "gamma" (light = grey^gamma) or '
        '"table" (measured, e.g. by heliotrack calibrate fisheye response).',
    )
    gamma: float | None = setting(None, doc='Exponent of response = "gamma".', gt=1.0, le=4.0)
    table: tuple[float, ...] | None = setting(
        None,
        doc='Light at each grey level 0..255 (256 values, non-decreasing; any scale) for response = "table".',
    )
    vignetting: tuple[float, ...] = setting(
        (),
        doc="Relative illumination of the lens, 1 + c1 t^2 + c2 t^4 + ... with t the field angle "
        "in radians: [c1, c2, ...] (at most 4).",
    )
    method: str | None = setting(None, doc="How it was obtained (free text).")

    def __schema_check__(self, at: Where) -> RadiometryCal:
        if self.response == "gamma" and self.gamma is None:
            raise at.child("gamma").error('a number (response = "gamma" needs its exponent)')
        if self.response != "gamma" and self.gamma is not None:
            raise at.child("gamma").error(f'no gamma (response = "{self.response}")', self.gamma)
        if self.response == "table":
            t = np.asarray(self.table if self.table is not None else (), float)
            if (
                t.shape != (256,)
                or not np.isfinite(t).all()
                or t[0] < 0
                or (np.diff(t) < 0).any()
                or t[-1] <= t[0]
            ):
                raise at.child("table").error(
                    "256 finite values, non-negative, non-decreasing, the last above the first",
                    f"{t.size} values" if t.shape != (256,) else "a table that is not",
                )
        elif self.table is not None:
            raise at.child("table").error(f'no table (response = "{self.response}")', "a table")
        if len(self.vignetting) > 4 or not all(math.isfinite(c) for c in self.vignetting):
            raise at.child("vignetting").error("at most 4 finite coefficients", list(self.vignetting))
        th = np.radians(np.linspace(0.0, VIGNETTING_CHECK_DEG, 101))
        v = relative_illumination(self.vignetting, np.cos(th))
        if float(v.min()) < VIGNETTING_MIN or float(v.max()) > 1.0 / VIGNETTING_MIN:
            raise at.child("vignetting").error(
                f"an illumination between {VIGNETTING_MIN} and {1 / VIGNETTING_MIN:g} of the centre's "
                f"out to {VIGNETTING_CHECK_DEG:g} deg",
                list(self.vignetting),
            )
        return self


def relative_illumination(coeffs: tuple[float, ...], cos_theta: np.ndarray) -> np.ndarray:
    """The lens's relative illumination ``1 + c1 t^2 + c2 t^4 + ...`` at the field angles
    whose cosines are ``cos_theta`` (``t`` in radians)."""
    t2 = np.arccos(np.clip(np.asarray(cos_theta, float), -1.0, 1.0)) ** 2
    v = np.ones_like(t2)
    p = np.ones_like(t2)
    for c in coeffs:
        p = p * t2
        v = v + c * p
    return v


@dataclass(frozen=True, kw_only=True)
class FisheyeBundle:
    """The fisheye sky camera's calibration bundle."""

    camera: CameraCal = setting(doc='Lens intrinsics; model = "fisheye" (cv2.fisheye).')
    orientation: OrientationCal | None = setting(None, doc="Rotation to ENU.")
    site: SiteCal | None = setting(None, doc="Site of the camera.")
    mount: MountCal | None = setting(
        None, doc="A panel camera's rotation on its panel (without it: its axis is the panel's normal)."
    )
    radiometry: RadiometryCal | None = setting(
        None, doc="Response and vignetting (without it: linear and evenly lit)."
    )
    mask: Path | None = setting(None, doc="Mask image of the camera's size (white = use).", path="file")
    notes: dict[str, Any] = setting(
        default_factory=dict, doc="Free-form notes of the calibration run (ignored)."
    )
    path: Path | None = internal(None)

    def __schema_check__(self, at: Where) -> FisheyeBundle:
        if self.camera.model != "fisheye":
            raise (
                at.child("camera")
                .child("model")
                .error(
                    '"fisheye" (a cv2.fisheye lens; without the key a camera is a pinhole one)',
                    self.camera.model,
                )
            )
        if self.mount is not None and self.orientation is not None:
            raise at.child("mount").error(
                "no [mount] beside an [orientation]: a sky camera's bundle has its rotation to ENU, "
                "a panel camera's its rotation on the panel",
                "a [mount] table",
            )
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
    """Validate an already parsed bundle (``path``: where relative paths resolve).

    ``camera.dist`` may be given as ``cv2.fisheye.calibrate`` returns D, a 4 x 1 array
    (``D.tolist()``: ``[[k1], [k2], [k3], [k4]]``)."""
    cam = doc.get("camera")
    if isinstance(cam, dict):
        dist = cam.get("dist")
        if isinstance(dist, list) and dist and all(isinstance(d, list) and len(d) == 1 for d in dist):
            doc = {**doc, "camera": {**cam, "dist": [d[0] for d in dist]}}
    return replace(load(FisheyeBundle, doc, str(path) if path is not None else None), path=path)


def fisheye_bundle_to_toml(b: FisheyeBundle, folder: Path | None = None) -> str:
    """Serialise; the mask's path is written relative to ``folder`` when inside it."""
    out = ["# heliotrack fisheye sky-camera calibration bundle (see docs/fisheye.md)"]
    if b.mask is not None:
        out.append(f"mask = {toml_value(relative_path(b.mask, folder))}")
    out += camera_section(b.camera, "fisheye")
    o = b.orientation
    if o is not None:
        out += _rotation_table("orientation", "enu_from_camera", o)
        if o.sky_scale != 1.0:
            out.append(f"sky_scale = {toml_value(o.sky_scale)}")
        if o.sky_calibration is not None:
            out.append(f"sky_calibration = {toml_value(list(o.sky_calibration))}")
        if o.locator is not None:
            out.append(f"locator = {toml_value(o.locator)}")
    r = b.radiometry
    if r is not None:
        out += ["", "[radiometry]", f"response = {toml_value(r.response)}"]
        if r.gamma is not None:
            out.append(f"gamma = {toml_value(r.gamma)}")
        if r.table is not None:
            out.append(f"table = {toml_value(list(r.table))}")
        if r.vignetting:
            out.append(f"vignetting = {toml_value(list(r.vignetting))}")
        if r.method is not None:
            out.append(f"method = {toml_value(r.method)}")
    if b.site is not None:
        s = b.site
        out += [
            "",
            "[site]",
            f"latitude = {toml_value(s.latitude)}",
            f"longitude = {toml_value(s.longitude)}",
            f"altitude = {toml_value(s.altitude)}",
        ]
    if b.mount is not None:
        out += _rotation_table("mount", "panel_from_camera", b.mount)
    out += notes_section(b.notes)
    return "\n".join(out) + "\n"


def _rotation_table(table: str, key: str, cal: OrientationCal | MountCal) -> list[str]:
    """``[table]`` with its rotation ``key`` and the fit's residual, method and frames."""
    out = ["", f"[{table}]", f"{key} = [" + ", ".join(toml_value(list(r)) for r in getattr(cal, key)) + "]"]
    if cal.residual_deg is not None:
        out.append(f"residual_deg = {toml_value(cal.residual_deg)}")
    if cal.method is not None:
        out.append(f"method = {toml_value(cal.method)}")
    if cal.frames is not None:
        out.append(f"frames = {int(cal.frames)}")
    return out


def save_fisheye_bundle(b: FisheyeBundle, path: str | Path) -> Path:
    """Write atomically if it reads back valid, so a failure loses nothing already stored."""
    path = Path(path)
    return write_if_valid(
        path, fisheye_bundle_to_toml(b, path.parent), lambda doc, at: fisheye_bundle_from_dict(doc, at)
    )


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
