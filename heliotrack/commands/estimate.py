"""``heliotrack estimate``: sun direction from images of the hotspot sensor, one JSON per line.

The image's time comes from ``--time``, else from an ISO timestamp in the file name
in one of the forms of :mod:`controller.timestamps` (canonical: ``2025-06-21T10-15-00Z``),
else it is omitted.  Frames that cannot be used print ``"found": false`` with a ``reason``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from controller.errors import InputError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("estimate", help="estimate the sun's direction from sensor images (JSON lines)")
    p.add_argument(
        "--sensor",
        choices=("hotspot", "fisheye"),
        default="hotspot",
        help="sensor type: the convex-surface hotspot sensor, or the fisheye sky camera",
    )
    p.add_argument("--calib", required=True, type=Path, help="calibration bundle (TOML)")
    p.add_argument("--time", default=None, help="ISO time of the image(s), UTC unless an offset is given")
    p.add_argument(
        "--algorithm",
        choices=("default", "seed"),
        default="default",
        help="default pipeline, or the paper's (hotspot: Algorithm 1 literally; "
        "fisheye: HSI weights, longitude correction and three rules)",
    )
    p.add_argument(
        "--method",
        choices=("subpixel", "paper"),
        default=None,
        help="hotspot only: direction from the hotspot, sub-pixel (default) or the paper's "
        "weights (the fisheye's paper pipeline is --algorithm seed)",
    )
    p.add_argument(
        "--causal",
        action="store_true",
        help="fisheye, default pipeline: read each frame by a camera that has learned from the "
        "frames before it only, as `heliotrack run` does (default: the batch's first half by a "
        "camera that has read its second half first; docs/fisheye.md, 'A batch of frames')",
    )
    p.add_argument("images", nargs="+", type=Path, metavar="IMAGE")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.sensor == "fisheye":
        from . import estimate_fisheye

        if args.method is not None:
            # silently ignored, it would look like a comparison of two methods that was not made
            raise InputError(
                "--method chooses the hotspot sensor's direction method; "
                "for the fisheye's paper pipeline give --algorithm seed"
            )

        return estimate_fisheye.run(args)
    if args.causal:
        raise InputError(
            "--causal is for the fisheye sky camera (--sensor fisheye); hotspot frames are read alone"
        )
    from controller.calibration.bundle import load_bundle
    from controller.timestamps import parse_timestamp, time_from_name, to_iso
    from controller.vision import HotspotEstimator

    bundle = load_bundle(args.calib)
    est = HotspotEstimator(bundle, algorithm=args.algorithm, method=args.method or "subpixel")
    t_cli = parse_timestamp(args.time, "--time") if args.time else None
    if t_cli is None:
        from heliotrack.output import warn_names_without_zone

        warn_names_without_zone(args.images)
    for path in args.images:
        t = t_cli if t_cli is not None else time_from_name(str(path))
        res = est.estimate_file(path, t)
        d = res.to_json()
        if t is not None:
            d["time"] = to_iso(t)
        sys.stdout.write(json.dumps(d) + "\n")
        sys.stdout.flush()
    return 0
