"""The calibration bundle of the hotspot sensor: one TOML file.

```toml
[camera]            # OpenCV intrinsics
width = 1280
height = 1024
fx = 1450.0
fy = 1450.0
cx = 640.0
cy = 512.0
dist = [k1, k2, p1, p2, k3]
rms_px = 0.05       # optional, reprojection RMS of the intrinsic calibration

[surface]           # model frame, metres; either an analytic sphere ...
kind = "sphere"
center = [0.0, 0.0, 0.0]
radius = 0.2
min_z = 0.0         # optional: the hemisphere is z >= min_z (default: center z)
# ... or a point cloud with (or without) normals: cloud = "globe.ply"

[pose]              # model -> camera (X_cam = R X_model + t); either rvec/tvec ...
rvec = [..]
tvec = [..]
# ... or markers_model = [[x, y, z], ...] with markers_image = [[u, v], ...] to solve

[level]             # either zenith_model = [x, y, z] or plumb_lines_image = [[[u1,v1],[u2,v2]], ...]
zenith_model = [0.0, 0.0, 1.0]

[azimuth]           # az_enu = (az_levelled - offset_deg) mod 360
offset_deg = 0.0

[lobe]              # optional: the glint centre sits coeff_deg * tan(incidence) off the
coeff_deg = 0.1     # mirror direction, away from the camera (fitted against the ephemeris)

mask = "mask.png"   # optional (top level); relative paths resolve against this file's folder
```
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


def vec3(v) -> Vec3:
    """Three floats from any 3-sequence (numpy arrays included)."""
    x, y, z = (float(c) for c in v)
    return x, y, z


@dataclass(frozen=True)
class SurfaceCal:
    """The convex surface in the model frame (metres): an analytic sphere or a point cloud."""

    kind: Literal["sphere", "cloud"] | None = setting(
        None,
        doc='"sphere" (center, radius) or "cloud" (cloud = path).',
        derived='"cloud" when cloud is given',
    )
    center: Vec3 = setting((0.0, 0.0, 0.0), doc="Sphere centre.", unit="m")
    radius: float = setting(0.0, doc="Sphere radius.", unit="m", ge=0)
    min_z: float | None = setting(
        None, doc="The hemisphere is z >= min_z (default: the centre's z).", unit="m"
    )
    cloud: Path | None = setting(
        None,
        doc="Point cloud of the surface (PLY, XYZ or NPZ; normals by local plane fit when absent).",
        path="file",
    )
    rmse_m: float | None = setting(None, doc="RMS residual of the sphere fit.", unit="m", ge=0)
    radial_poly_degree: int | None = setting(
        None, doc="Degree of the sphere's radial shape correction.", ge=0, le=12
    )
    radial_poly: tuple[float, ...] | None = setting(None, doc="Coefficients of the radial shape correction.")

    def __schema_check__(self, at: Where) -> SurfaceCal:
        if self.kind is None:
            if self.cloud is None:
                raise at.child("kind").error('"sphere" (center, radius) or "cloud" (cloud = path)')
            return replace(self, kind="cloud").__schema_check__(at)
        if self.kind == "sphere" and not self.radius > 0:
            raise at.child("radius").error("a positive number (m) for a sphere", self.radius)
        if self.kind == "cloud" and self.cloud is None:
            raise at.child("cloud").error("a path to a PLY, XYZ or NPZ point cloud")
        if (self.radial_poly is None) != (self.radial_poly_degree is None):
            raise at.child("radial_poly").error("both radial_poly_degree and radial_poly, or neither")
        if self.radial_poly_degree is not None and self.radial_poly is not None:
            n = sum((d + 1) * (d + 2) // 2 for d in range(self.radial_poly_degree + 1))
            if len(self.radial_poly) != n:
                raise at.child("radial_poly").error(
                    f"{n} coefficients for degree {self.radial_poly_degree}", len(self.radial_poly)
                )
        return self


@dataclass(frozen=True)
class PoseCal:
    """Model -> camera (``X_cam = R X_model + t``): rvec/tvec, or markers to solve by PnP."""

    rvec: Vec3 | None = setting(None, doc="Rotation vector (OpenCV, model to camera).", unit="rad")
    tvec: Vec3 | None = setting(None, doc="Translation (model to camera).", unit="m")
    markers_model: tuple[Vec3, ...] | None = setting(
        None, doc="Surveyed marker points in the model frame (at least 4).", unit="m"
    )
    markers_image: tuple[tuple[float, float], ...] | None = setting(
        None, doc="The markers' image points, in the same order.", unit="px"
    )
    rms_px: float | None = setting(None, doc="Reprojection RMS of the pose.", unit="px", ge=0)

    def __schema_check__(self, at: Where) -> PoseCal:
        if self.rvec is not None or self.tvec is not None:
            if self.rvec is None or self.tvec is None:
                raise at.error("both rvec and tvec")
            if max(abs(x) for x in self.rvec) > 4 * np.pi:  # 1e300 rad made a NaN rotation
                raise at.child("rvec").error("a rotation vector of at most 4 pi rad", list(self.rvec))
            # a survey in mm, say (hypot: a fuzzed 1e200 overflowed numpy's norm, with a warning)
            if math.hypot(*self.tvec) > MAX_CAMERA_DISTANCE_M:
                raise at.child("tvec").error(
                    f"a camera within {MAX_CAMERA_DISTANCE_M:g} m of the surface's model origin "
                    "(is the survey in metres?)",
                    list(self.tvec),
                )
            return self
        if self.markers_model is None and self.markers_image is None:
            raise at.error("rvec and tvec, or markers_model and markers_image")
        mm, mi = self.markers_model or (), self.markers_image or ()
        if len(mm) < 4:
            raise at.child("markers_model").error("at least 4 points", len(mm))
        if len(mm) != len(mi):
            raise at.child("markers_image").error(
                f"as many points as pose.markers_model ({len(mm)})", len(mi)
            )
        if np.linalg.matrix_rank(np.asarray(mm, float) - np.mean(mm, axis=0), tol=1e-9) < 2:
            raise at.child("markers_model").error("points that do not all lie on one line or point", len(mm))
        return self


#: The farthest a hotspot camera may stand from its surface's model origin (m).
MAX_CAMERA_DISTANCE_M = 20.0
#: The largest tilt of the dome's axis from the zenith a bundle may state (deg).
MAX_TILT_DEG = 45.0


@dataclass(frozen=True)
class LevelCal:
    """Which way is up in the model frame: the zenith, or plumb lines seen in an image."""

    zenith_model: Vec3 | None = setting(None, doc="Zenith direction in the model frame.")
    plumb_lines_image: tuple[tuple[tuple[float, float], ...], ...] | None = setting(
        None, doc="Plumb lines in the plumb view: at least 2 lines of >= 2 image points.", unit="px"
    )

    def __schema_check__(self, at: Where) -> LevelCal:
        if self.zenith_model is not None:
            norm = math.hypot(*self.zenith_model)  # no overflow for a huge vector
            if norm < 1e-9:
                raise at.child("zenith_model").error("a non-zero vector", list(self.zenith_model))
            # the model's z is the dome's axis, installed about level: a zenith far from it
            # (plumb lines that were not vertical, a sign flipped) saw nothing but `below_horizon`
            tilt = float(np.degrees(np.arccos(np.clip(self.zenith_model[2] / norm, -1, 1))))
            if tilt > MAX_TILT_DEG:
                raise at.child("zenith_model").error(
                    f"a zenith within {MAX_TILT_DEG:g} deg of the model's z axis (the dome's), "
                    f"not {tilt:.1f} deg",
                    list(self.zenith_model),
                )
            return self
        lines = self.plumb_lines_image
        if lines is None:
            raise at.error("zenith_model or plumb_lines_image")
        if len(lines) < 2:
            raise at.child("plumb_lines_image").error(
                "at least 2 lines, each [[u1, v1], [u2, v2], ...]", len(lines)
            )
        for i, line in enumerate(lines):
            if len(line) < 2:
                raise at.child("plumb_lines_image").item(i).error("at least 2 points", len(line))
        return self


@dataclass(frozen=True)
class AzimuthCal:
    """Azimuth alignment: ``az_enu = (az_levelled - offset_deg) mod 360``."""

    offset_deg: float = setting(
        doc="Azimuth offset of the levelled model frame.", unit="deg", ge=-360, le=720
    )


@dataclass(frozen=True)
class LobeCal:
    """The glint centre sits ``coeff_deg * tan(incidence)`` off the mirror direction, away
    from the camera (fitted against the ephemeris)."""

    coeff_deg: float = setting(doc="Lobe-offset coefficient.", unit="deg")


@dataclass(frozen=True, kw_only=True)
class CalibrationBundle:
    """The hotspot sensor's calibration bundle."""

    camera: CameraCal = setting(doc="Intrinsics.")
    surface: SurfaceCal | None = setting(None, doc="The convex surface.")
    pose: PoseCal | None = setting(None, doc="Model-to-camera pose.")
    level: LevelCal | None = setting(None, doc="Levelling.")
    azimuth: AzimuthCal | None = setting(None, doc="Azimuth alignment.")
    lobe: LobeCal | None = setting(None, doc="Glint lobe offset.")
    mask: Path | None = setting(None, doc="Mask image (white = use).", path="file")
    notes: dict[str, Any] = setting(
        default_factory=dict, doc="Free-form notes of the calibration run (ignored)."
    )
    path: Path | None = internal(None)

    @property
    def azimuth_offset_deg(self) -> float | None:
        return self.azimuth.offset_deg if self.azimuth is not None else None

    @property
    def lobe_coeff_deg(self) -> float | None:
        return self.lobe.coeff_deg if self.lobe is not None else None

    # -- derived -------------------------------------------------------------------------
    def require(self, what: str) -> None:
        if what == "surface" and self.surface is None:
            raise ConfigError(self.path, "surface", "a [surface] table (sphere or cloud)")
        if what == "pose" and self.pose is None:
            raise ConfigError(self.path, "pose", "a [pose] table (rvec/tvec or markers)")

    def solved_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(rvec, tvec) model -> camera; solves PnP from markers when only those are given."""
        self.require("pose")
        p = self.pose
        assert p is not None
        if p.rvec is not None and p.tvec is not None:
            return np.asarray(p.rvec, float), np.asarray(p.tvec, float)
        from .pose import solve_pose

        res = solve_pose(np.asarray(p.markers_model, float), np.asarray(p.markers_image, float), self.camera)
        return res.rvec, res.tvec

    def zenith(self) -> np.ndarray | None:
        """Unit zenith in the model frame, or None when the bundle has no levelling."""
        if self.level is None:
            return None
        if self.level.zenith_model is not None:
            z = np.asarray(self.level.zenith_model, float)
            return z / np.linalg.norm(z)
        from .level import zenith_from_lines

        rvec, _ = self.solved_pose()
        return zenith_from_lines(
            np.asarray(self.level.plumb_lines_image, float), self.camera, rvec
        ).zenith_model


def load_bundle(path: str | Path) -> CalibrationBundle:
    """Read and validate a bundle; errors name the file, the key and what was expected."""
    try:
        b = load_file(CalibrationBundle, path)
    except ConfigError as exc:
        if _is_fisheye(path):  # the other camera's bundle: say so rather than name a key
            raise ConfigError(
                path,
                "camera.model",
                "a hotspot camera's bundle (this is a fisheye sky camera's: --sensor fisheye)",
            ) from exc
        raise
    return replace(b, path=Path(path))


def _is_fisheye(path: str | Path) -> bool:
    """Whether the TOML file at ``path`` declares a fisheye lens (``[camera] model``)."""
    import tomllib

    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    camera = doc.get("camera")
    return isinstance(camera, dict) and camera.get("model") == "fisheye"


def bundle_from_dict(doc: dict[str, Any], path: Path | None = None) -> CalibrationBundle:
    """Validate an already parsed bundle (``path``: where relative paths resolve)."""
    b = load(CalibrationBundle, doc, str(path) if path is not None else None)
    return replace(b, path=path)


def bundle_to_toml(b: CalibrationBundle, folder: Path | None = None) -> str:
    """Serialise; paths are written relative to ``folder`` when inside it."""

    def rel(p: Path) -> str:
        return relative_path(p, folder)

    out = ["# heliotrack hotspot-sensor calibration bundle (see docs/hotspot.md)"]
    if b.mask is not None:
        out.append(f"mask = {toml_value(rel(b.mask))}")
    c = b.camera
    out += camera_section(c, c.model if c.model != "pinhole" else None)
    if b.surface is not None:
        s = b.surface
        out += ["", "[surface]", f"kind = {toml_value(s.kind)}"]
        if s.kind == "sphere":
            out += [f"center = {toml_value(list(s.center))}", f"radius = {toml_value(s.radius)}"]
            if s.rmse_m is not None:
                out.append(f"rmse_m = {toml_value(s.rmse_m)}")
            if s.radial_poly is not None:
                out += [
                    f"radial_poly_degree = {s.radial_poly_degree}",
                    f"radial_poly = {toml_value(list(s.radial_poly))}",
                ]
        else:
            assert s.cloud is not None  # a cloud surface names its file (checked on load)
            out.append(f"cloud = {toml_value(rel(s.cloud))}")
        if s.min_z is not None:
            out.append(f"min_z = {toml_value(s.min_z)}")
    if b.pose is not None:
        p = b.pose
        out += ["", "[pose]"]
        if p.rvec is not None:
            out += [f"rvec = {toml_value(p.rvec)}", f"tvec = {toml_value(p.tvec)}"]
            if p.rms_px is not None:
                out.append(f"rms_px = {toml_value(p.rms_px)}")
        else:
            out += [
                f"markers_model = {toml_value(p.markers_model)}",
                f"markers_image = {toml_value(p.markers_image)}",
            ]
    if b.level is not None:
        out += ["", "[level]"]
        if b.level.zenith_model is not None:
            out.append(f"zenith_model = {toml_value(b.level.zenith_model)}")
        else:
            out.append(f"plumb_lines_image = {toml_value(b.level.plumb_lines_image)}")
    if b.azimuth_offset_deg is not None:
        out += ["", "[azimuth]", f"offset_deg = {toml_value(b.azimuth_offset_deg)}"]
    if b.lobe_coeff_deg is not None:
        out += ["", "[lobe]", f"coeff_deg = {toml_value(b.lobe_coeff_deg)}"]
    out += notes_section(b.notes)
    return "\n".join(out) + "\n"


def save_bundle(b: CalibrationBundle, path: str | Path) -> Path:
    """Write atomically if it reads back valid, so a failure loses nothing already stored."""
    path = Path(path)
    return write_if_valid(path, bundle_to_toml(b, path.parent), lambda doc, at: bundle_from_dict(doc, at))


def update_bundle(path: str | Path, **changes) -> CalibrationBundle:
    """Load (or start) the bundle at ``path``, replace fields, save; returns the new bundle."""
    path = Path(path)
    if path.exists():
        b = load_bundle(path)
    else:
        if "camera" not in changes:
            raise ConfigError(path, "camera", "intrinsics first (heliotrack calibrate intrinsics)")
        b = CalibrationBundle(camera=changes["camera"], path=path)
    b = replace(b, **changes)
    save_bundle(b, path)
    return replace(b, path=path)
