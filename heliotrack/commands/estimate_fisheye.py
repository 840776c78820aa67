"""``heliotrack estimate --sensor fisheye``: the sky camera's sun, one JSON line per image.

The images of one call are one sequence: they are processed in time order (the time of
each from the timestamp in its file name, canonical form ``2026-03-20T10-15-00Z.png``, or
from ``--time`` for a single image; images without a time keep their place after the
timed ones), so the previous accepted detection gates the next (the paper's rule 3, in
angle).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from controller.errors import InputError


def frame_times(images: list[Path], t_cli: float | None) -> list[tuple[float | None, Path]]:
    """(time, path) in processing order: timed images by time, then untimed ones as given."""
    from controller.timestamps import time_from_name

    timed: list[tuple[float, int, Path]] = []
    untimed: list[tuple[None, int, Path]] = []
    for i, p in enumerate(images):
        t = t_cli if t_cli is not None else time_from_name(str(p))
        if t is not None:
            timed.append((t, i, p))
        else:
            untimed.append((None, i, p))
    timed.sort(key=lambda x: (x[0], x[1]))
    return [(t, p) for t, _, p in timed] + [(None, p) for _, _, p in untimed]


def make_estimator(calib: Path, algorithm: str):
    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.vision.fisheye import FisheyeEstimator, SeedEstimator

    bundle = load_fisheye_bundle(calib)
    return SeedEstimator(bundle) if algorithm == "seed" else FisheyeEstimator(bundle)


def run(args: argparse.Namespace) -> int:
    from controller.timestamps import parse_timestamp, to_iso

    if args.time and len(args.images) > 1:
        # several fisheye images are one sequence, gated frame to frame: one time for all
        # would make every step a jump of zero seconds
        raise InputError("--time stamps a single image; several images take their times from their names")
    est = make_estimator(args.calib, args.algorithm)
    t_cli = parse_timestamp(args.time, "--time") if args.time else None
    for t, path in frame_times(list(args.images), t_cli):
        d = est.estimate_file(path, t).to_json()
        if t is not None:
            d["time"] = to_iso(t)
        sys.stdout.write(json.dumps(d) + "\n")
        sys.stdout.flush()
    return 0
