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
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError


@dataclass(frozen=True)
class CameraCal:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    rms_px: float | None = None

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, float)


@dataclass(frozen=True)
class SurfaceCal:
    kind: str  # "sphere" or "cloud"
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    min_z: float | None = None
    cloud: Path | None = None
    rmse_m: float | None = None
    radial_poly_degree: int | None = None  # optional shape correction of the sphere
    radial_poly: tuple[float, ...] | None = None


@dataclass(frozen=True)
class PoseCal:
    rvec: tuple[float, float, float] | None = None
    tvec: tuple[float, float, float] | None = None
    markers_model: tuple[tuple[float, float, float], ...] | None = None
    markers_image: tuple[tuple[float, float], ...] | None = None
    rms_px: float | None = None


@dataclass(frozen=True)
class LevelCal:
    zenith_model: tuple[float, float, float] | None = None
    plumb_lines_image: tuple[tuple[tuple[float, float], ...], ...] | None = None


@dataclass(frozen=True)
class CalibrationBundle:
    camera: CameraCal
    surface: SurfaceCal | None = None
    pose: PoseCal | None = None
    level: LevelCal | None = None
    azimuth_offset_deg: float | None = None
    lobe_coeff_deg: float | None = None  # [lobe] coeff_deg: glint-centre offset model
    mask: Path | None = None
    path: Path | None = None
    notes: dict = field(default_factory=dict)

    # -- derived -------------------------------------------------------------------------
    def require(self, what: str):
        if what == "surface" and self.surface is None:
            raise ConfigError(self.path, "surface", "a [surface] table (sphere or cloud)")
        if what == "pose" and self.pose is None:
            raise ConfigError(self.path, "pose", "a [pose] table (rvec/tvec or markers)")

    def solved_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(rvec, tvec) model -> camera; solves PnP from markers when only those are given."""
        self.require("pose")
        p = self.pose
        if p.rvec is not None and p.tvec is not None:
            return np.asarray(p.rvec, float), np.asarray(p.tvec, float)
        from .pose import solve_pose

        res = solve_pose(np.asarray(p.markers_model, float), np.asarray(p.markers_image, float),
                         self.camera)
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
        return zenith_from_lines(np.asarray(self.level.plumb_lines_image, float), self.camera,
                                 rvec).zenith_model


# ------------------------------------------------------------------------------------------
def _num(v, file, key, *, positive=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(file, key, "a finite number", v)
    if positive and v <= 0:
        raise ConfigError(file, key, "a positive number", v)
    return float(v)


def _vec(v, n, file, key):
    if not isinstance(v, list) or len(v) != n:
        raise ConfigError(file, key, f"a list of {n} numbers", v)
    return tuple(_num(x, file, f"{key}[{i}]") for i, x in enumerate(v))


def _vecs(v, n, file, key, min_len=1):
    if not isinstance(v, list) or len(v) < min_len:
        raise ConfigError(file, key, f"a list of at least {min_len} [{n} numbers] items", v)
    return tuple(_vec(x, n, file, f"{key}[{i}]") for i, x in enumerate(v))


def _table(doc, name, file):
    t = doc.get(name)
    if t is None:
        return None
    if not isinstance(t, dict):
        raise ConfigError(file, name, "a table", t)
    return t


def _radial(srf: dict, file) -> dict:
    if "radial_poly" not in srf and "radial_poly_degree" not in srf:
        return {}
    deg = srf.get("radial_poly_degree")
    if not isinstance(deg, int) or isinstance(deg, bool) or not 0 <= deg <= 12:
        raise ConfigError(file, "surface.radial_poly_degree", "an integer 0..12", deg)
    n = sum((d + 1) * (d + 2) // 2 for d in range(deg + 1))
    return {"radial_poly_degree": deg,
            "radial_poly": _vec(srf.get("radial_poly"), n, file, "surface.radial_poly")}


def load_bundle(path: str | Path) -> CalibrationBundle:
    """Read and validate a bundle; errors name the file, the key and what was expected."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(path, "", f"a readable calibration bundle ({exc.strerror})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, "", f"valid TOML ({exc})") from None
    return bundle_from_dict(doc, path)


def bundle_from_dict(doc: dict, path: Path | None = None) -> CalibrationBundle:
    file = path
    folder = path.parent if path is not None else Path(".")
    known = {"camera", "surface", "pose", "level", "azimuth", "lobe", "mask", "notes"}
    for k in doc:
        if k not in known:
            raise ConfigError(file, k, f"one of {sorted(known)}", k)
    cam = _table(doc, "camera", file)
    if cam is None:
        raise ConfigError(file, "camera", "a [camera] table with width height fx fy cx cy dist")
    for k in ("width", "height"):
        if not isinstance(cam.get(k), int) or isinstance(cam.get(k), bool) or cam[k] <= 0:
            raise ConfigError(file, f"camera.{k}", "a positive integer", cam.get(k))
    for k in ("fx", "fy", "cx", "cy"):
        if k not in cam:
            raise ConfigError(file, f"camera.{k}", "a number")
    dist = cam.get("dist", [0.0] * 5)
    if not isinstance(dist, list) or len(dist) not in (4, 5, 8, 12, 14):
        raise ConfigError(file, "camera.dist", "[k1, k2, p1, p2, k3] (OpenCV order)", dist)
    camera = CameraCal(
        width=cam["width"], height=cam["height"],
        fx=_num(cam["fx"], file, "camera.fx", positive=True),
        fy=_num(cam["fy"], file, "camera.fy", positive=True),
        cx=_num(cam["cx"], file, "camera.cx"), cy=_num(cam["cy"], file, "camera.cy"),
        dist=tuple(_num(x, file, f"camera.dist[{i}]") for i, x in enumerate(dist)),
        rms_px=_num(cam["rms_px"], file, "camera.rms_px") if "rms_px" in cam else None,
    )

    surface = None
    srf = _table(doc, "surface", file)
    if srf is not None:
        kind = srf.get("kind", "cloud" if "cloud" in srf else None)
        if kind == "sphere":
            surface = SurfaceCal(
                kind="sphere", center=_vec(srf.get("center"), 3, file, "surface.center"),
                radius=_num(srf.get("radius"), file, "surface.radius", positive=True),
                min_z=_num(srf["min_z"], file, "surface.min_z") if "min_z" in srf else None,
                rmse_m=_num(srf["rmse_m"], file, "surface.rmse_m") if "rmse_m" in srf else None,
                **_radial(srf, file))
        elif kind == "cloud":
            c = srf.get("cloud")
            if not isinstance(c, str) or not c:
                raise ConfigError(file, "surface.cloud", "a path to a PLY, XYZ or NPZ point cloud", c)
            cp = (folder / c) if not Path(c).is_absolute() else Path(c)
            if not cp.is_file():
                raise ConfigError(file, "surface.cloud", "an existing point-cloud file", str(cp))
            surface = SurfaceCal(kind="cloud", cloud=cp,
                                 min_z=_num(srf["min_z"], file, "surface.min_z") if "min_z" in srf else None)
        else:
            raise ConfigError(file, "surface.kind", '"sphere" (center, radius) or "cloud" (cloud = path)', kind)

    pose = None
    ps = _table(doc, "pose", file)
    if ps is not None:
        if "rvec" in ps or "tvec" in ps:
            pose = PoseCal(rvec=_vec(ps.get("rvec"), 3, file, "pose.rvec"),
                           tvec=_vec(ps.get("tvec"), 3, file, "pose.tvec"),
                           rms_px=_num(ps["rms_px"], file, "pose.rms_px") if "rms_px" in ps else None)
        elif "markers_model" in ps or "markers_image" in ps:
            mm = _vecs(ps.get("markers_model"), 3, file, "pose.markers_model", 4)
            mi = _vecs(ps.get("markers_image"), 2, file, "pose.markers_image", 4)
            if len(mm) != len(mi):
                raise ConfigError(file, "pose.markers_image",
                                  f"as many points as pose.markers_model ({len(mm)})", len(mi))
            pose = PoseCal(markers_model=mm, markers_image=mi)
        else:
            raise ConfigError(file, "pose", "rvec and tvec, or markers_model and markers_image")

    level = None
    lv = _table(doc, "level", file)
    if lv is not None:
        if "zenith_model" in lv:
            z = _vec(lv["zenith_model"], 3, file, "level.zenith_model")
            if np.linalg.norm(z) < 1e-9:
                raise ConfigError(file, "level.zenith_model", "a non-zero vector", list(z))
            level = LevelCal(zenith_model=z)
        elif "plumb_lines_image" in lv:
            pl = lv["plumb_lines_image"]
            if not isinstance(pl, list) or len(pl) < 2:
                raise ConfigError(file, "level.plumb_lines_image",
                                  "at least 2 lines, each [[u1, v1], [u2, v2], ...]", pl)
            lines = tuple(_vecs(line, 2, file, f"level.plumb_lines_image[{i}]", 2)
                          for i, line in enumerate(pl))
            level = LevelCal(plumb_lines_image=lines)
        else:
            raise ConfigError(file, "level", "zenith_model or plumb_lines_image")

    az = None
    at = _table(doc, "azimuth", file)
    if at is not None:
        az = _num(at.get("offset_deg"), file, "azimuth.offset_deg")

    lobe = None
    lt = _table(doc, "lobe", file)
    if lt is not None:
        lobe = _num(lt.get("coeff_deg"), file, "lobe.coeff_deg")

    mask = None
    if "mask" in doc:
        m = doc["mask"]
        if not isinstance(m, str) or not m:
            raise ConfigError(file, "mask", "a path to a mask image", m)
        mp = folder / m if not Path(m).is_absolute() else Path(m)
        if not mp.is_file():
            raise ConfigError(file, "mask", "an existing mask image file", str(mp))
        mask = mp
    notes = doc.get("notes", {})
    if surface is None or pose is None:
        pass  # intrinsics-only bundles are valid (calibration in progress)
    return CalibrationBundle(camera=camera, surface=surface, pose=pose, level=level,
                             azimuth_offset_deg=az, lobe_coeff_deg=lobe, mask=mask, path=path,
                             notes=notes if isinstance(notes, dict) else {})


# ------------------------------------------------------------------------------------------
def _fmt(v) -> str:
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


def bundle_to_toml(b: CalibrationBundle, folder: Path | None = None) -> str:
    """Serialise; paths are written relative to ``folder`` when inside it."""

    def rel(p: Path) -> str:
        if folder is not None:
            try:
                return str(Path(p).resolve().relative_to(Path(folder).resolve()))
            except ValueError:
                pass
        return str(p)

    out = ["# heliotrack hotspot-sensor calibration bundle (see docs/hotspot.md)"]
    if b.mask is not None:
        out.append(f"mask = {_fmt(rel(b.mask))}")
    c = b.camera
    out += ["", "[camera]", f"width = {c.width}", f"height = {c.height}",
            f"fx = {_fmt(c.fx)}", f"fy = {_fmt(c.fy)}", f"cx = {_fmt(c.cx)}", f"cy = {_fmt(c.cy)}",
            f"dist = {_fmt(list(c.dist))}"]
    if c.rms_px is not None:
        out.append(f"rms_px = {_fmt(c.rms_px)}")
    if b.surface is not None:
        s = b.surface
        out += ["", "[surface]", f"kind = {_fmt(s.kind)}"]
        if s.kind == "sphere":
            out += [f"center = {_fmt(list(s.center))}", f"radius = {_fmt(s.radius)}"]
            if s.rmse_m is not None:
                out.append(f"rmse_m = {_fmt(s.rmse_m)}")
            if s.radial_poly is not None:
                out += [f"radial_poly_degree = {s.radial_poly_degree}",
                        f"radial_poly = {_fmt(list(s.radial_poly))}"]
        else:
            out.append(f"cloud = {_fmt(rel(s.cloud))}")
        if s.min_z is not None:
            out.append(f"min_z = {_fmt(s.min_z)}")
    if b.pose is not None:
        p = b.pose
        out += ["", "[pose]"]
        if p.rvec is not None:
            out += [f"rvec = {_fmt(list(p.rvec))}", f"tvec = {_fmt(list(p.tvec))}"]
            if p.rms_px is not None:
                out.append(f"rms_px = {_fmt(p.rms_px)}")
        else:
            out += [f"markers_model = {_fmt([list(x) for x in p.markers_model])}",
                    f"markers_image = {_fmt([list(x) for x in p.markers_image])}"]
    if b.level is not None:
        out += ["", "[level]"]
        if b.level.zenith_model is not None:
            out.append(f"zenith_model = {_fmt(list(b.level.zenith_model))}")
        else:
            out.append("plumb_lines_image = "
                       + _fmt([[list(p) for p in line] for line in b.level.plumb_lines_image]))
    if b.azimuth_offset_deg is not None:
        out += ["", "[azimuth]", f"offset_deg = {_fmt(b.azimuth_offset_deg)}"]
    if b.lobe_coeff_deg is not None:
        out += ["", "[lobe]", f"coeff_deg = {_fmt(b.lobe_coeff_deg)}"]
    if b.notes:
        out += ["", "[notes]"]
        for k, v in b.notes.items():
            out.append(f"{k} = {_fmt(v)}")
    return "\n".join(out) + "\n"


def save_bundle(b: CalibrationBundle, path: str | Path) -> Path:
    """Write atomically (temp file + rename), so a failure loses nothing already stored."""
    import os

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(bundle_to_toml(b, path.parent))
    os.replace(tmp, path)
    return path


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
