"""``heliotrack calibrate STEP ...``: build the hotspot sensor's calibration bundle from images.

Each step updates (or starts) a bundle TOML; ``all`` runs the whole chain on a folder."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from controller.errors import InputError
from heliotrack.argtypes import LATITUDE, LONGITUDE, SQUARE_M, board_pattern, int_in, number_in


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate the hotspot or fisheye sensor (writes a bundle TOML)")
    p.set_defaults(func=lambda a: (p.print_help(), 2)[1])
    add_subcommands(p)


def add_subcommands(p: argparse.ArgumentParser) -> None:
    sp = p.add_subparsers(dest="calib_step", metavar="STEP")
    a = sp.add_parser("intrinsics", help="camera intrinsics from checkerboard images")
    a.add_argument(
        "--pattern", type=board_pattern, default="9x6", help="inner corners per row x per column (9x6)"
    )
    a.add_argument("--square", type=SQUARE_M, required=True, help="square size, metres")
    a.add_argument("--bundle", type=Path, required=True)
    a.add_argument("images", nargs="+", type=Path)
    a.set_defaults(func=_intrinsics)
    s = sp.add_parser("surface", help="surface model from a point cloud (PLY/XYZ/NPZ)")
    s.add_argument("--cloud", type=Path, required=True)
    s.add_argument(
        "--fit-sphere",
        action="store_true",
        help="store the fitted analytic sphere (the default; kept for older scripts)",
    )
    s.add_argument(
        "--keep-cloud",
        action="store_true",
        help="store the scan itself instead (experimental: not reliable, docs/hotspot.md Decisions)",
    )
    s.add_argument("--min-z", type=number_in(-10.0, 10.0), default=None, help="hemisphere cut (model z)")
    s.add_argument("--bundle", type=Path, required=True)
    s.set_defaults(func=_surface)
    q = sp.add_parser("pose", help="exterior orientation by PnP on base markers")
    q.add_argument("--image", type=Path, help="view with ArUco markers (automatic detection)")
    q.add_argument("--survey", type=Path, help="CSV id,corner,x,y,z of the markers (model frame)")
    q.add_argument("--picked", type=Path, help="hand-picked CSV x,y,z,u,v instead of detection")
    q.add_argument("--bundle", type=Path, required=True)
    q.set_defaults(func=_pose)
    lv = sp.add_parser("level", help="zenith from plumb lines (image or picked points)")
    lv.add_argument("--image", type=Path, help="view with plumb lines (automatic detection)")
    lv.add_argument("--lines", type=Path, help="CSV line,u,v of picked points (>= 2 per line)")
    lv.add_argument("--bundle", type=Path, required=True)
    lv.set_defaults(func=_level)
    az = sp.add_parser("azimuth", help="azimuth offset from a day of levelled observations")
    az.add_argument(
        "--observations", type=Path, required=True, help="JSON lines from `heliotrack estimate` (with times)"
    )
    az.add_argument("--method", choices=("noon", "ephemeris"), default="noon")
    az.add_argument(
        "--culminates",
        choices=("south", "north"),
        help="where the sun's highest point lies (noon method; default: from the sense of the "
        "sun's motion when the observations have times, else from --lat outside the tropics, "
        "else south, the paper's assumption)",
    )
    az.add_argument("--lat", type=LATITUDE)
    az.add_argument("--lon", type=LONGITUDE)
    az.add_argument("--bundle", type=Path, required=True)
    az.set_defaults(func=_azimuth)
    al = sp.add_parser("all", help="the whole chain from an installer's folder (see docs/hotspot.md)")
    al.add_argument(
        "folder",
        type=Path,
        help="checkerboards/, globe_scan.ply, markers_survey.csv, marker_view.png, plumb_view.png, day/",
    )
    al.add_argument("--pattern", type=board_pattern, default="9x6")
    al.add_argument("--square", type=SQUARE_M, default=0.04)
    al.add_argument("--lat", type=LATITUDE, help="site latitude (enables the ephemeris azimuth fit)")
    al.add_argument("--lon", type=LONGITUDE)
    al.add_argument(
        "--min-z", type=number_in(-10.0, 10.0), default=0.0, help="hemisphere cut in the model frame"
    )
    al.add_argument(
        "--method",
        choices=("noon", "ephemeris", "ephemeris-full"),
        default="ephemeris",
        help="azimuth alignment: paper's noon culmination; ephemeris azimuth fit; or "
        "full rotation fit against the ephemeris (replaces the plumb-line zenith)",
    )
    al.add_argument(
        "--shape-degree",
        type=int_in(0, 12),
        default=6,
        help="degree of the radial shape polynomial fitted to the scan (0: sphere only)",
    )
    al.add_argument("--bundle", type=Path, required=True)
    al.set_defaults(func=_all)
    from . import calibrate_fisheye

    calibrate_fisheye.add_parser(sp)


def _grey(path):
    from controller.vision.imageio import load_grey

    img, reason = load_grey(path)
    if img is None:
        raise InputError(f"{path}: {reason}")
    return img


def _intrinsics(args) -> int:
    from controller.calibration.bundle import update_bundle
    from controller.calibration.intrinsics import calibrate_intrinsics

    res = calibrate_intrinsics(
        [str(p) for p in args.images], args.pattern, args.square, [str(p) for p in args.images]
    )
    update_bundle(args.bundle, camera=res.camera)
    print(
        json.dumps(
            {
                "step": "intrinsics",
                "rms_px": round(res.rms_px, 4),
                "views": len(res.used),
                "rejected": res.rejected,
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


def _surface(args) -> int:
    from controller.calibration.bundle import SurfaceCal, update_bundle, vec3
    from controller.calibration.surface import fit_sphere

    if args.fit_sphere and args.keep_cloud:
        raise InputError("surface: --fit-sphere and --keep-cloud exclude each other")
    if not args.keep_cloud:
        f = fit_sphere(args.cloud)
        if args.min_z is not None and args.min_z >= f.center[2] + f.radius:
            raise InputError(
                f"surface: --min-z {args.min_z:g} m is above the fitted sphere's top "
                f"({f.center[2] + f.radius:.4f} m): nothing of it would be left"
            )
        srf = SurfaceCal(
            kind="sphere",
            center=vec3(f.center),
            radius=f.radius,
            min_z=args.min_z,
            rmse_m=f.rmse_m,
        )
        info = {
            "radius_m": round(f.radius, 6),
            "center": [round(float(x), 6) for x in f.center],
            "rmse_mm": round(1000 * f.rmse_m, 4),
            "points": f.n_points,
        }
    else:
        from controller.calibration.surface import load_cloud

        pts, _ = load_cloud(args.cloud)
        srf = SurfaceCal(kind="cloud", cloud=args.cloud.resolve(), min_z=args.min_z)
        info = {
            "points": len(pts),
            "note": "the cloud mode is not reliable (docs/hotspot.md, Decisions): prefer the fitted sphere",
        }
    update_bundle(args.bundle, surface=srf)
    print(json.dumps({"step": "surface", **info, "bundle": str(args.bundle)}))
    return 0


def _pose(args) -> int:
    from controller.calibration.bundle import PoseCal, load_bundle, update_bundle, vec3
    from controller.calibration.pose import detect_markers, read_marker_survey, read_picked, solve_pose

    b = load_bundle(args.bundle)
    if args.picked:
        mp, ip = read_picked(args.picked)
    elif args.image and args.survey:
        mp, ip = detect_markers(_grey(args.image), read_marker_survey(args.survey))
    else:
        raise InputError("pose: give --image with --survey, or --picked")
    res = solve_pose(mp, ip, b.camera)
    update_bundle(
        args.bundle,
        pose=PoseCal(rvec=vec3(res.rvec), tvec=vec3(res.tvec), rms_px=res.rms_px),
    )
    print(
        json.dumps(
            {
                "step": "pose",
                "points": res.n_points,
                "rms_px": round(res.rms_px, 4),
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


def _level(args) -> int:
    from controller.calibration.bundle import LevelCal, load_bundle, update_bundle, vec3
    from controller.calibration.level import detect_plumb_lines, zenith_from_lines

    b = load_bundle(args.bundle)
    rvec, _ = b.solved_pose()
    if args.lines:
        try:
            a = np.loadtxt(args.lines, delimiter=",", skiprows=1, ndmin=2)
        except (OSError, ValueError) as exc:
            raise InputError(f"{args.lines}: expected CSV line,u,v ({exc})") from None
        bad = np.flatnonzero(~np.isfinite(a).all(axis=1)) if a.ndim == 2 else np.zeros(0, int)
        if a.ndim != 2 or a.shape[1] < 3 or len(a) == 0 or bad.size:
            where = f"row {bad[0] + 2}: not finite" if bad.size else "expected rows line,u,v"
            raise InputError(f"{args.lines}: {where}")
        lines = [a[a[:, 0] == k, 1:3] for k in np.unique(a[:, 0])]
        res = zenith_from_lines(lines, b.camera, rvec)
    elif args.image:
        lines = detect_plumb_lines(_grey(args.image), b.camera)
        if len(lines) < 2:
            raise InputError(
                f"{args.image}: found {len(lines)} plumb lines, need >= 2 (pick points by hand: --lines)"
            )
        res = zenith_from_lines(lines, b.camera, rvec, undistorted=True)
    else:
        raise InputError("level: give --image or --lines")
    update_bundle(args.bundle, level=LevelCal(zenith_model=vec3(res.zenith_model)))
    print(
        json.dumps(
            {
                "step": "level",
                "lines": res.n_lines,
                "rms_line_deg": round(res.rms_line_deg, 4),
                "zenith_model": [round(float(x), 8) for x in res.zenith_model],
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


def _azimuth(args) -> int:

    from controller.calibration.azimuth import ephemeris_offset, noon_offset
    from controller.calibration.bundle import AzimuthCal, update_bundle

    az, el, ts = [], [], []
    try:
        text = args.observations.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(
            f"{args.observations}: expected JSON lines from heliotrack estimate ({exc})"
        ) from None
    for ln, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
        except json.JSONDecodeError:
            raise InputError(f"{args.observations}:{ln}: not JSON") from None
        if not isinstance(d, dict):
            raise InputError(f"{args.observations}:{ln}: expected a JSON object from heliotrack estimate")
        if not d.get("found") or "levelled_az_deg" not in d:
            continue
        a, e = d.get("levelled_az_deg"), d.get("levelled_el_deg")
        if not all(isinstance(x, (int, float)) and math.isfinite(x) for x in (a, e)):
            raise InputError(f"{args.observations}:{ln}: levelled_az_deg, levelled_el_deg: expected numbers")
        az.append(a)
        el.append(e)
        ts.append(d.get("time"))
    from controller.timestamps import parse_timestamp

    timed = bool(ts) and all(t is not None for t in ts)
    tt = [parse_timestamp(str(t), f"{args.observations}: time") for t in ts] if timed else None
    extra: dict[str, str] = {}
    if args.method == "noon":
        culminates, extra["culminates_from"] = _culmination(args, az, el, tt)
        extra["culminates"] = culminates
        off = noon_offset(az, el, culminates)
    else:
        if args.lat is None or args.lon is None or tt is None:
            raise InputError("the ephemeris method needs --lat, --lon and times in the observations")
        from controller.sun.source import Site, solar_position

        sp = solar_position(Site(args.lat, args.lon), tt)
        off = ephemeris_offset(az, el, sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy())
    update_bundle(args.bundle, azimuth=AzimuthCal(off))
    print(
        json.dumps(
            {
                "step": "azimuth",
                "method": args.method,
                "observations": len(az),
                **extra,
                "offset_deg": round(off, 4),
                "bundle": str(args.bundle),
            }
        )
    )
    return 0


#: Outside these latitudes (deg) the sun culminates on the equator's side all year.
TROPIC_DEG = 23.45


def _culmination(args, az, el, times) -> tuple[str, str]:
    """Where the sun culminates for the noon method, and what said so.  The paper assumed
    the south: south of the equator that put the offset 180 deg off (an audit at -33.9)."""
    from controller.calibration.azimuth import culmination

    moving = culmination(az, el, times)
    if moving is not None:
        if args.culminates is not None and args.culminates != moving:
            way = "east, south, west" if moving == "south" else "east, north, west"
            raise InputError(
                f"--culminates {args.culminates}: the observations' sun culminates in the {moving} "
                f"(it moves {way}); check --culminates, or the observations' times"
            )
        return moving, "the sun's motion"
    if args.culminates is not None:
        return args.culminates, "--culminates"
    if args.lat is not None and abs(args.lat) >= TROPIC_DEG:
        return ("south" if args.lat > 0 else "north"), "--lat"
    if args.lat is not None:
        raise InputError(
            f"the noon method at latitude {args.lat:g}: between the tropics the sun culminates "
            "north or south by season; give the observations' times or --culminates"
        )
    return "south", "assumed (no times, no --lat, no --culminates)"


def _all(args) -> int:
    from controller.calibration.chain import calibrate_folder
    from controller.sun.source import Site

    if not args.folder.is_dir():
        what = "not found" if not args.folder.exists() else "not a folder"
        raise InputError(f"{args.folder}: {what}: expected an installer's folder (see docs/hotspot.md)")
    site = Site(args.lat, args.lon) if args.lat is not None and args.lon is not None else None
    calibrate_folder(
        args.folder,
        pattern=args.pattern,
        square=args.square,
        site=site,
        min_z=args.min_z,
        method=args.method,
        out=args.bundle,
        shape_degree=args.shape_degree,
        log=lambda d: print(json.dumps(d)),
    )
    print(json.dumps({"bundle": str(args.bundle)}))
    return 0
