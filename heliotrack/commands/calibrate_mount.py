"""``heliotrack calibrate fisheye mount``: a panel camera's rotation on its panel.

The panel-mounted closed loop cannot see a camera mounted off its panel's normal: it puts
the sun on the camera's axis, and the panel sits off the sun by the mount
(docs/fisheye.md, "On a plant").  At commissioning, frames from the panel's camera, each
named with its UTC time, and the panel's true angles logged beside them (an inclinometer
on the panel; for a dual-axis azimuth, a survey or the homed encoder) give the sun in both
frames; :func:`controller.calibration.fisheye_mount.fit_mount` fits the rotation, written
as the lens bundle's ``[mount]``, which ``run``, ``check`` and ``simulate`` then apply.

The plant file gives the site and the tracker's geometry (``--config``, ``--tracker``).
One JSON line; errors in the input are one plain line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from controller.errors import ConfigError, InputError
from heliotrack.argtypes import number_in

GAP_S = number_in(0.0, 3600.0)


def add_parser(steps: argparse._SubParsersAction) -> None:
    """Add ``mount`` to ``heliotrack calibrate fisheye``'s steps."""
    m = steps.add_parser(
        "mount",
        help="a panel camera's rotation on its panel, from its sun sightings and the panel's true angles",
        description="Frames from a panel camera (file names with their UTC time) and a CSV of the "
        "panel's true angles at those times (columns time, and rotation, or azimuth and "
        "elevation, deg) -> the lens bundle's [mount].  Hold the panel at a few angles (stow, "
        "and 20-40 deg either side) while the sun crosses the image, so that the camera's turn "
        "about its own axis is fixed too.  See docs/fisheye.md, 'On a plant'.",
    )
    m.add_argument("--config", type=Path, required=True, help="the plant file (site, tracker geometry)")
    m.add_argument("--tracker", required=True, help="the tracker whose panel carries the camera")
    m.add_argument(
        "--angles", type=Path, required=True, help="CSV: time, and the panel's true angle per axis (deg)"
    )
    m.add_argument(
        "--max-gap",
        type=GAP_S,
        default=5.0,
        metavar="S",
        help="a frame without an angle reading this close in time (s) is left out (default 5)",
    )
    m.add_argument("--bundle", type=Path, required=True, help="the camera's lens bundle (updated)")
    m.add_argument("images", nargs="+", type=Path, help="panel-camera frames named with their UTC time")
    m.set_defaults(func=run)


def _plant(path: Path):
    """The plant file, or a simulator scenario (its [hil] table ignored here)."""
    from controller.config import load_config
    from heliotrack.scenario import load_scenario

    try:
        return load_config(path)
    except ConfigError as exc:
        if exc.key != "hil":
            raise
    return load_scenario(path)


def run(args: argparse.Namespace) -> int:
    from controller.calibration.fisheye_bundle import (
        MountCal,
        as_mat3,
        load_fisheye_bundle,
        update_fisheye_bundle,
    )
    from controller.calibration.fisheye_mount import angles_at, fit_mount, panel_frame, read_panel_angles
    from controller.calibration.fisheye_orientation import sun_vectors
    from controller.closedloop.pose import axis_names
    from controller.config import SingleAxisTracker
    from controller.vision.fisheye import FisheyeEstimator

    from .estimate_fisheye import frame_times, sized_frame

    config = _plant(args.config)
    trackers = {tr.name: tr for tr in config.trackers}
    if args.tracker not in trackers:
        raise InputError(
            f"mount: --tracker: expected a tracker of {args.config} ({', '.join(trackers)}), got {args.tracker!r}"
        )
    tr = trackers[args.tracker]
    row = tr if isinstance(tr, SingleAxisTracker) else None
    bundle = load_fisheye_bundle(args.bundle)
    if bundle.orientation is not None:
        raise InputError(
            f"mount: {args.bundle} has an [orientation]: a sky camera's bundle; a panel camera's "
            "lens bundle has none (the camera turns with its panel)"
        )
    readings = read_panel_angles(args.angles, axis_names(tr))
    estimator = FisheyeEstimator(bundle)
    times, d_cam, sigmas, panels = [], [], [], []
    rejected: dict[str, str] = {}
    for t, path in frame_times(list(args.images), None):
        if t is None:
            raise InputError(f"{path}: no timestamp in the file name (e.g. 2026-03-20T10-15-00Z.png)")
        angles = angles_at(readings, t, args.max_gap)
        if angles is None:
            rejected[str(path)] = f"no panel angle within {args.max_gap:g} s"
            continue
        estimator.reset_sequence()  # the panel may have turned between frames
        res = estimator.estimate_image(sized_frame(path, bundle.camera), None)
        if not res.found or res.d_cam is None:
            rejected[str(path)] = res.reason or "not found"
            continue
        times.append(t)
        d_cam.append(np.asarray(res.d_cam, float))
        sigmas.append(res.sigma_deg if res.sigma_deg is not None else math.nan)
        panels.append(panel_frame(tr.type, angles, *((row.axis_azimuth, row.axis_tilt) if row else ())))
    if len(times) < 3:
        raise InputError(
            f"mount: the sun found in {len(times)} of {len(args.images)} frame(s), need at least 3"
            + (f" ({'; '.join(f'{k}: {v}' for k, v in list(rejected.items())[:3])})" if rejected else "")
        )
    s_enu = sun_vectors(config.site, times)
    s_panel = np.stack([P.T @ s for P, s in zip(panels, s_enu)])
    sig = np.asarray(sigmas, float)
    fit = fit_mount(np.stack(d_cam), s_panel, np.where(np.isfinite(sig), sig, np.nanmax(sig, initial=0.05)))
    update_fisheye_bundle(
        args.bundle,
        mount=MountCal(
            panel_from_camera=as_mat3(fit.panel_from_camera),
            residual_deg=round(fit.residual_deg, 5),
            method="sun+panel angles",
            frames=fit.used,
        ),
    )
    axis = fit.panel_from_camera[:, 2]  # the camera's axis in the panel's frame
    print(
        json.dumps(
            {
                "step": "fisheye mount",
                "tracker": tr.name,
                "frames": len(args.images),
                "used": fit.used,
                "rejected": rejected,
                "residual_deg": round(fit.residual_deg, 4),
                "axis_off_deg": round(fit.axis_off_deg, 4),
                # where the camera's axis leans in the panel's frame: towards +x (increasing
                # azimuth or rotation) and +y; a row's loop without [mount] leaves its panel
                # this far off the sun in rotation (x)
                "axis_lean_deg": {
                    "x": round(math.degrees(math.atan2(axis[0], axis[2])), 4),
                    "y": round(math.degrees(math.atan2(axis[1], axis[2])), 4),
                },
                "rotvec_deg": [round(float(x), 4) for x in fit.rotvec_deg],
                "sigma_deg": [round(float(x), 4) for x in fit.sigma_deg],
                "determined": list(fit.determined),
                "bundle": str(args.bundle),
            }
        )
    )
    return 0
