"""``heliotrack calibrate fisheye lens|orientation|level|response|vignetting|mount``: the sky
camera's bundle from images.

* ``lens``: ``cv2.fisheye.calibrate`` on checkerboard views -> ``[camera]``.
* ``orientation``: a day of sky frames (file names with timestamps) and the site -> the
  rotation to ENU from the camera's own sun detections (Kabsch, then refined on pixels
  together with the lens's focal lengths, principal point and k1, k2, held to their
  checkerboard values by priors; ``--refine rotation`` keeps the lens) -> ``[orientation]``,
  ``[site]`` and the refined ``[camera]``.  The frames are then measured again with that
  rotation, and the scale of the sky's correction of the glare's rim is fitted with it
  (``[orientation] sky_scale``; ``--sky-scale none`` leaves it at 1), or, when it cuts the
  residual further, a scale for each sky model linear in the air mass, fitted on the frames
  with their column smear taken off (``[orientation] sky_calibration``).
  ``--horizon IMAGE`` adds the horizon's zenith as a constraint and reports the agreement.
  A fit that cannot be the camera's is refused before anything is written: no rotation
  within 0.5 deg of the sun's path (mirrored frames), a camera tilted more than
  ``--max-tilt`` (30 deg), or a horizon more than 1 deg from the sun's zenith; a wrong
  latitude or longitude sign or a clock zone turns the fit rather than failing it.
* ``level``: the zenith from the horizon in one clear frame; prints the tilt and residual,
  and the disagreement with the bundle's orientation when it has one.
* ``response``: brackets of one still scene at several exposures -> ``[radiometry]``'s
  measured response table (the vignetting kept).
* ``vignetting``: flat fields through the bundle's lens and response -> ``[radiometry]``'s
  vignetting (the response kept).  docs/fisheye-radiometry-calibration.md.
* ``mount``: a panel camera's rotation on its panel, from its sun sightings and the panel's
  true angles -> ``[mount]`` (:mod:`.calibrate_mount`).

Each prints one JSON line per step; errors in the input are one plain line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import numpy as np

from controller.errors import InputError
from heliotrack.argtypes import SQUARE_M, board_pattern, number_in

from .estimate_fisheye import sized_frame

TILT_DEG = number_in(0.0, 180.0)


def add_parser(sp: argparse._SubParsersAction) -> None:
    """Add ``fisheye`` (with its steps) to ``heliotrack calibrate``'s sub-parsers."""
    f = sp.add_parser(
        "fisheye",
        help="the fisheye sky camera: lens, orientation, level, response, vignetting; a panel camera's mount",
    )
    f.set_defaults(func=lambda a: (f.print_help(), 2)[1])
    steps = f.add_subparsers(dest="fisheye_step", metavar="STEP")
    a = steps.add_parser("lens", help="lens (cv2.fisheye K, D) from checkerboard images")
    a.add_argument(
        "--pattern", type=board_pattern, default="9x6", help="inner corners per row x per column (9x6)"
    )
    a.add_argument("--square", type=SQUARE_M, required=True, help="square size, metres")
    a.add_argument("--bundle", type=Path, required=True)
    a.add_argument("images", nargs="+", type=Path)
    a.set_defaults(func=_lens)
    o = steps.add_parser(
        "orientation",
        help="rotation to ENU from a day of the camera's sun detections (site and frame times known)",
    )
    o.add_argument("--lat", type=float, help="site latitude, deg north (else the bundle's [site])")
    o.add_argument("--lon", type=float, help="site longitude, deg east")
    o.add_argument("--alt", type=float, default=0.0, help="site altitude, m")
    o.add_argument(
        "--refine",
        choices=("none", "rotation", "lens"),
        default="lens",
        help="refine on pixels: the rotation and the lens (default; the lens held to "
        "its checkerboard values by priors), the rotation only, or not",
    )
    o.add_argument("--horizon", type=Path, help="a clear frame whose horizon constrains the zenith")
    o.add_argument(
        "--sky-scale",
        choices=("fit", "none"),
        default="fit",
        help="fit the scale of the sky's correction of the rim with the rotation (default; "
        "kept at 1 unless it cuts the residual by 15 %%), or leave it at 1",
    )
    o.add_argument(
        "--max-tilt",
        type=TILT_DEG,
        metavar="DEG",
        help="refuse a fit that tilts the camera more than this from the zenith (default 30: "
        "a sky camera stands near level, and a wrong site sign or clock zone turns the fit "
        "instead of failing it)",
    )
    o.add_argument("--bundle", type=Path, required=True)
    o.add_argument("images", nargs="+", type=Path, help="sky frames named with their UTC time")
    o.set_defaults(func=_orientation)
    lv = steps.add_parser("level", help="zenith from the horizon in one frame (prints; no write)")
    lv.add_argument("--bundle", type=Path, required=True)
    lv.add_argument("image", type=Path)
    lv.set_defaults(func=_level)
    doc = "See docs/fisheye-radiometry-calibration.md."
    r = steps.add_parser(
        "response",
        help="the camera's response (grey -> light) from brackets of one still scene",
        description="Frames of one still scene (tripod; aperture, gain and white balance fixed) at "
        "exposures 1 EV apart (at most 2 EV), from one in which the brightest part of the scene is "
        "below mid-grey to one in which the darkest part is above it.  Writes [radiometry] "
        'response = "table" (the vignetting kept).  ' + doc,
    )
    r.add_argument(
        "--times",
        type=float,
        nargs="+",
        metavar="T",
        help="exposure time of each image, seconds, in the images' order (after the images, or "
        "before them with -- ending the list); without it, each file name gives its time as "
        "_e<seconds> before the extension, e.g. dome_e0.004.png",
    )
    r.add_argument("--bundle", type=Path, required=True)
    r.add_argument("images", nargs="+", type=Path, help="at least 3 frames, all the same size")
    r.set_defaults(func=_response)
    what = (
        "Frames of a uniformly lit target filling the view (an integrating dome, an evenly "
        "overcast sky through a diffuser), exposed so that nothing near the axis saturates; "
        "fitted through the bundle's lens and response.  Writes [radiometry] vignetting (the "
        "response kept; linear if there is none yet).  "
    )
    v = steps.add_parser(
        "vignetting", help="the lens's relative illumination from flat fields", description=what + doc
    )
    v.add_argument(
        "--order",
        type=int,
        choices=(1, 2, 3, 4),
        default=3,
        help="coefficients of 1 + c1 t^2 + c2 t^4 + ... (default 3)",
    )
    v.add_argument("--bundle", type=Path, required=True)
    v.add_argument("images", nargs="+", type=Path, help="at least 3 flat-field frames, all the same size")
    v.set_defaults(func=_vignetting)
    from . import calibrate_mount

    calibrate_mount.add_parser(steps)


def _grey(path: Path) -> np.ndarray:
    from controller.vision.imageio import load_grey

    img, reason = load_grey(path)
    if img is None:
        raise InputError(f"{path}: {reason}")
    return img


def _lens(args) -> int:
    from controller.calibration.fisheye_bundle import update_fisheye_bundle
    from controller.calibration.fisheye_lens import calibrate_fisheye

    views = [(str(p), _grey(p)) for p in args.images]
    h, w = views[0][1].shape[:2]
    res = calibrate_fisheye(views, (w, h), args.pattern, args.square)
    update_fisheye_bundle(args.bundle, camera=res.camera)
    print(
        json.dumps(
            {
                "step": "fisheye lens",
                "rms_px": round(res.rms_px, 4),
                "views": len(res.used),
                "rejected": res.rejected,
                "fx": round(res.camera.fx, 3),
                "cx": round(res.camera.cx, 3),
                "cy": round(res.camera.cy, 3),
                "dist": [round(x, 6) for x in res.camera.dist],
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


def _site(args, bundle):
    from controller.calibration.fisheye_bundle import SiteCal

    for flag, value, lo, hi in (
        ("--lat", args.lat, -90, 90),
        ("--lon", args.lon, -180, 180),
        ("--alt", args.alt, -500, 9000),
    ):
        if value is not None and not (math.isfinite(value) and lo <= value <= hi):
            raise InputError(f"orientation: {flag}: expected a number in [{lo}, {hi}], got {value}")
    if (args.lat is None) != (args.lon is None):
        raise InputError("orientation: give both --lat and --lon (or neither, to use the bundle's [site])")
    if args.lat is not None and args.lon is not None:
        return SiteCal(latitude=args.lat, longitude=args.lon, altitude=args.alt)
    if bundle.site is not None:
        return bundle.site
    raise InputError("orientation: give --lat and --lon (or a [site] in the bundle)")


def _orientation(args) -> int:
    from controller.calibration.fisheye_bundle import load_fisheye_bundle, save_fisheye_bundle
    from controller.calibration.fisheye_orientation import check_plausible, level_from_horizon
    from controller.calibration.fisheye_sun_calibration import calibrate_from_sun

    from .estimate_fisheye import frame_times

    bundle = load_fisheye_bundle(args.bundle)
    site = _site(args, bundle)
    frames = []
    for t, path in frame_times(list(args.images), None):
        if t is None:
            raise InputError(f"{path}: no timestamp in the file name (e.g. 2026-03-20T10-15-00Z.png)")
        frames.append((t, path))
    zen = None
    if args.horizon is not None:
        zen = level_from_horizon(sized_frame(args.horizon, bundle.camera), bundle.camera).zenith_cam
    cal = calibrate_from_sun(
        bundle,
        frames,
        site,
        refine=None if args.refine == "none" else args.refine,
        horizon_zenith_cam=zen,
        fit_scale=args.sky_scale == "fit",
    )
    tilt = {} if args.max_tilt is None else {"max_tilt_deg": args.max_tilt}
    check_plausible(cal.fit, **tilt)  # before anything is written
    save_fisheye_bundle(cal.bundle, args.bundle)
    fit, o = cal.fit, cal.bundle.orientation
    assert o is not None
    out: dict[str, object] = {
        "step": "fisheye orientation",
        "method": o.method,
        "frames": len(args.images),
        "detections": cal.detections,
        "not_found": cal.not_found,
        "used": fit.used,
        "rejected": fit.rejected,
        "residual_deg": round(fit.residual_deg, 4),
        "tilt_deg": round(fit.tilt_deg, 4),
        "bundle": str(args.bundle),
    }
    if fit.residual_px is not None:
        out["residual_px"] = round(fit.residual_px, 4)
    if fit.horizon_disagreement_deg is not None:
        out["horizon_disagreement_deg"] = round(fit.horizon_disagreement_deg, 4)
    if cal.sky is not None:
        out["sky_scale"] = round(cal.sky.scale, 4)
        out["sky_scale_fitted"] = round(cal.sky.fitted, 4)
        out["sky_scale_residual_deg"] = [
            round(cal.sky.residual_unscaled_deg, 4),
            round(cal.sky.residual_deg, 4),
        ]
    if cal.calibration is not None:
        c = cal.calibration
        out["sky_calibration"] = [round(k, 4) for k in c.coefficients] if c.adopted else None
        out["sky_calibration_fitted"] = [round(k, 4) for k in c.coefficients]
        out["sky_calibration_residual_deg"] = [round(c.residual_compared_deg, 4), round(c.residual_deg, 4)]
    if cal.locator is not None:  # the rim against the sky's rings (each with its own rotation)
        loc = cal.locator
        out["locator"] = loc.locator
        out["locator_residual_deg"] = {
            "rim": round(loc.rim_residual_deg, 4),
            "rings": round(loc.rings_residual_deg, 4),
        }
    print(json.dumps(out))
    return 0


def _level(args) -> int:
    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.calibration.fisheye_orientation import level_from_horizon

    bundle = load_fisheye_bundle(args.bundle)
    lv = level_from_horizon(sized_frame(args.image, bundle.camera), bundle.camera)
    out = {
        "step": "fisheye level",
        "zenith_cam": [round(float(x), 7) for x in lv.zenith_cam],
        "tilt_deg": round(lv.tilt_deg, 4),
        "residual_deg": round(lv.residual_deg, 4),
        "points": lv.points,
        "rejected": lv.rejected,
    }
    if bundle.enu_from_camera is not None:
        z = bundle.enu_from_camera.T @ np.array([0.0, 0.0, 1.0])
        out["disagreement_with_orientation_deg"] = round(
            math.degrees(math.acos(float(np.clip(z @ lv.zenith_cam, -1, 1)))), 4
        )
    print(json.dumps(out))
    return 0


#: ``<stem>_e<seconds>.<ext>``: the exposure time in a bracket's file name.
_EXPOSURE_RE = re.compile(r"_e(\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)$")


def _frames(paths: list[Path], step: str) -> list[np.ndarray]:
    from controller.vision.fisheye import load_frame

    if len(paths) < 3:
        raise InputError(f"{step}: {len(paths)} image(s), need at least 3")
    out: list[np.ndarray] = []
    for p in paths:
        img, reason = load_frame(p)
        if img is None:
            raise InputError(f"{p}: {reason}")
        if out and img.shape != out[0].shape:
            h0, w0 = out[0].shape[:2]
            raise InputError(f"{p}: {img.shape[1]}x{img.shape[0]}, but {paths[0]} is {w0}x{h0}")
        out.append(img)
    return out


def _exposure_times(args) -> list[float]:
    if args.times is not None:
        if len(args.times) != len(args.images):
            raise InputError(f"--times: {len(args.times)} time(s) for {len(args.images)} image(s)")
        return list(args.times)
    times = []
    for p in args.images:
        m = _EXPOSURE_RE.search(Path(p).stem)
        if m is None:
            raise InputError(
                f"{p}: no exposure time in the name (e.g. dome_e0.004.png for 0.004 s); or give --times"
            )
        times.append(float(m.group(1)))
    return times


def _existing(path: Path):
    """The bundle at ``path`` (it must hold the lens already)."""
    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.errors import ConfigError

    if not path.exists():
        raise ConfigError(path, "camera", "the lens first (heliotrack calibrate fisheye lens ...)")
    return load_fisheye_bundle(path)


def _method_parts(method: str | None) -> tuple[list[str], list[str]]:
    """A ``[radiometry]`` method split into its response parts and its ``vignetting: ...``
    parts (the two steps each keep the other's)."""
    parts = [x.strip() for x in (method or "").split(";") if x.strip()]
    return (
        [x for x in parts if not x.startswith("vignetting:")],
        [x for x in parts if x.startswith("vignetting:")],
    )


def _radiometry(bundle_path: Path, **fields):
    """A validated ``[radiometry]`` (errors name the bundle and the key)."""
    from controller.calibration.fisheye_bundle import RadiometryCal
    from controller.schema import load

    doc = {
        k: (list(v) if isinstance(v, tuple | np.ndarray) else v) for k, v in fields.items() if v is not None
    }
    return load(RadiometryCal, doc, bundle_path, "radiometry")


def _response(args) -> int:
    from controller.calibration import fisheye_radiometry as fr
    from controller.calibration.fisheye_bundle import update_fisheye_bundle

    bundle = _existing(args.bundle)
    times = _exposure_times(args)
    frames = _frames(list(args.images), "response")
    table = fr.response_from_brackets(frames, times, names=[str(p) for p in args.images])
    old = bundle.radiometry
    _, keep = _method_parts(old.method if old is not None else None)
    cal = _radiometry(
        args.bundle,
        response="table",
        table=[round(float(x), 7) for x in table],
        vignetting=old.vignetting if old is not None else (),
        method="; ".join([f"debevec, {len(frames)} frames", *keep]),
    )
    update_fisheye_bundle(args.bundle, radiometry=cal)
    print(
        json.dumps(
            {
                "step": "fisheye response",
                "frames": len(frames),
                "max_dev_srgb": round(fr.response_deviation(table, fr.srgb_response()), 4),
                "max_dev_linear": round(fr.response_deviation(table, fr.linear_response()), 4),
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


def _vignetting(args) -> int:
    from dataclasses import replace

    import cv2

    from controller.calibration.fisheye_bundle import update_fisheye_bundle
    from controller.calibration.fisheye_radiometry import vignetting_from_flats
    from controller.errors import ConfigError
    from controller.vision.fisheye.lens import FisheyeLens
    from controller.vision.fisheye.radiometry import Radiometry

    bundle = _existing(args.bundle)
    frames = _frames(list(args.images), "vignetting")
    mask = None
    if bundle.mask is not None:
        mask = cv2.imread(str(bundle.mask), cv2.IMREAD_GRAYSCALE)
        if mask is None or mask.shape != frames[0].shape[:2]:
            h, w = frames[0].shape[:2]
            raise ConfigError(args.bundle, "mask", f"a readable {w}x{h} mask image", str(bundle.mask))
    old = bundle.radiometry
    # the response only: the fit measures the vignetting afresh
    rad = Radiometry.from_cal(replace(old, vignetting=()) if old is not None else None)
    fit = vignetting_from_flats(
        frames,
        FisheyeLens.from_camera(bundle.camera),
        rad,
        order=args.order,
        mask=mask,
        names=[str(p) for p in args.images],
    )
    coeffs = [round(c, 7) for c in fit.coeffs]
    resp, _ = _method_parts(old.method if old is not None else None)
    cal = _radiometry(
        args.bundle,
        response=old.response if old is not None else "linear",
        gamma=old.gamma if old is not None else None,
        table=old.table if old is not None else None,
        vignetting=coeffs,
        method="; ".join([*resp, f"vignetting: flat field, {len(frames)} frames"]),
    )
    update_fisheye_bundle(args.bundle, radiometry=cal)
    print(
        json.dumps(
            {
                "step": "fisheye vignetting",
                "frames": len(frames),
                "order": args.order,
                "vignetting": coeffs,
                "rms": round(fit.rms, 5),
                "field_deg": [round(fit.theta_min_deg, 2), round(fit.theta_max_deg, 2)],
                "bins": fit.bins,
                "bundle": str(args.bundle),
            }
        )
    )
    return 0
