"""``heliotrack estimate --sensor fisheye``: the sky camera's sun, one JSON line per image.

The images of one call are one sequence: they are processed in time order (the time of
each from the timestamp in its file name, canonical form ``2026-03-20T10-15-00Z.png``, or
from ``--time`` for a single image; images without a time keep their place after the
timed ones), so the previous accepted detection gates the next (the paper's rule 3, in
angle).  The default pipeline reads the timed frames as a batch
(:func:`controller.vision.fisheye.batch.estimate_batch`): the first half by a camera that
has learned from the second half, so that no frame is read by a camera that has learned
nothing; ``--causal`` reads each from the frames before it alone, as ``heliotrack run``
does.  The lines are then printed once the batch is read.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from controller.errors import InputError

log = logging.getLogger("heliotrack.estimate")


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


def sized_frame(path: Path, camera) -> np.ndarray:
    """The frame at ``path``, of the bundle's lens's size (else a one-line error)."""
    from controller.vision.fisheye import load_frame

    img, reason = load_frame(path)
    if img is None:
        raise InputError(f"{path}: {reason}")
    if img.shape[:2] != (camera.height, camera.width):
        raise InputError(
            f"{path}: size_mismatch (expected {camera.width}x{camera.height}, got {img.shape[1]}x{img.shape[0]})"
        )
    return img


def make_estimator(calib: Path, algorithm: str):
    """A function that makes a fresh estimator of ``algorithm`` for the bundle at ``calib``
    (read and checked once)."""
    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.vision.fisheye import FisheyeEstimator, SeedEstimator

    bundle = load_fisheye_bundle(calib)
    return (lambda: SeedEstimator(bundle)) if algorithm == "seed" else (lambda: FisheyeEstimator(bundle))


def run(args: argparse.Namespace) -> int:
    from controller.timestamps import parse_timestamp, to_iso

    if args.time and len(args.images) > 1:
        # several fisheye images are one sequence, gated frame to frame: one time for all
        # would make every step a jump of zero seconds
        raise InputError("--time stamps a single image; several images take their times from their names")
    make = make_estimator(args.calib, args.algorithm)
    t_cli = parse_timestamp(args.time, "--time") if args.time else None
    order = frame_times(list(args.images), t_cli)
    if t_cli is None:
        from heliotrack.output import warn_names_without_zone

        warn_names_without_zone(args.images)
    untimed = [p for t, p in order if t is None]
    if untimed and len(order) > 1:
        log.warning(
            "%d of %d frames have no time in their names (%s%s): they are measured after the "
            "timed ones, in the order given, without the ephemeris and sequence gates; name them "
            "like 2026-03-20T10-15-00Z.png",
            len(untimed),
            len(order),
            untimed[0].name,
            ", ..." if len(untimed) > 1 else "",
        )
    seen = GateTally()
    for t, d in measured(make, order, args.algorithm == "default" and not args.causal):
        if t is not None:
            d["time"] = to_iso(t)
        seen.add(d)
        sys.stdout.write(json.dumps(d) + "\n")
        sys.stdout.flush()
    turned = seen.turned_by()
    if turned is not None:
        log.warning(seen.turned_warning(turned))
    elif seen.says_the_bundle_is_wrong():
        log.warning(seen.warning())
    return 0


def measured(
    make, order: list[tuple[float | None, Path]], batch: bool
) -> Iterator[tuple[float | None, dict]]:
    """(time, JSON line) of each frame of ``order``, in its order: the timed frames as one
    batch when ``batch`` (:func:`controller.vision.fisheye.batch.estimate_batch`), else each
    as it comes; the untimed ones after them, by the camera that read the timed ones in order."""
    from controller.vision.fisheye.batch import estimate_batch

    timed = [(t, p) for t, p in order if t is not None]
    est = make()
    rest: list[tuple[float | None, Path]] = list(order)
    if batch and len(timed) > 1:
        results = estimate_batch(make, timed, lambda e, f: e.estimate_file(f[1], f[0]), forward=est)
        for (tt, _), r in zip(timed, results):
            yield tt, r.to_json()
        rest = rest[len(timed) :]  # the untimed: by ``est``, which has read the timed in order
    for t, p in rest:
        yield t, est.estimate_file(p, t).to_json()


class GateTally:
    """Frames whose glare the ephemeris gate refused, and by how far.

    A glare found frame after frame, always several degrees from where the sun must be, is
    the sun seen through a wrong bundle or clock, not a distractor: a transposed
    ``enu_from_camera``, a wrong ``[site]``, or frames named in local time.  Each frame
    then reads only ``gate_rejected``, which names none of these."""

    MIN_FRAMES = 3
    MIN_BEYOND_DEG = 2.0

    def __init__(self) -> None:
        self.glare = 0  # frames with a sun-like glare: found, or refused by a gate
        self.beyond: list[float] = []
        self.offsets: list[tuple[float, float]] = []  # the ephemeris gate's refused glares (deg)

    def add(self, d: dict) -> None:
        if d.get("found"):
            self.glare += 1
        elif d.get("reason") == "gate_rejected":
            self.glare += 1
            off = d.get("glare_offset_deg")
            if isinstance(off, list) and len(off) == 2:
                self.offsets.append((float(off[0]), float(off[1])))
            far = d.get("beyond_gate_deg")
            if (
                "ephemeris" in d.get("gates", ())
                and isinstance(far, (int, float))
                and far > self.MIN_BEYOND_DEG
            ):
                self.beyond.append(float(far))

    def turned_by(self) -> tuple[float, float] | None:
        """The one offset (deg: along the horizon, up) by which the ephemeris gate refused at
        least :data:`MIN_FRAMES` glares, half the frames with one or more, or None
        (:func:`controller.sun.mount_watch.one_offset`)."""
        import numpy as np

        from controller.sun.mount_watch import one_offset

        if len(self.offsets) < self.MIN_FRAMES or 2 * len(self.offsets) < self.glare:
            return None
        return one_offset(np.array(self.offsets))

    def turned_warning(self, off: tuple[float, float]) -> str:
        return (
            f"{len(self.offsets)} of the {self.glare} frames with a sun-like glare were refused by "
            f"the ephemeris gate, their glares all {math.hypot(*off):.2f} deg from where the sun must "
            f"be by one offset ({off[0]:+.2f} deg along the horizon, {off[1]:+.2f} up): the camera has "
            "turned since its orientation was calibrated (heliotrack calibrate fisheye orientation), "
            "or the bundle's [site] or the frames' times are off"
        )

    def says_the_bundle_is_wrong(self) -> bool:
        return len(self.beyond) >= self.MIN_FRAMES and 2 * len(self.beyond) >= self.glare

    def warning(self) -> str:
        far = sorted(self.beyond)[len(self.beyond) // 2]
        return (
            f"{len(self.beyond)} of the {self.glare} frames with a sun-like glare were refused by "
            f"the ephemeris gate, the glare a median {far:.1f} deg beyond it: the sun seen through "
            "a wrong bundle or clock. Check enu_from_camera (its columns are the camera's x, y, z "
            "axes in ENU: a transposed matrix?), the bundle's [site], and the frames' times (UTC, "
            "or with a zone in the name)"
        )
