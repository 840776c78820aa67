"""The fisheye benchmark's suites (frames rendered by ``hil.skycam``, scored against truth).

Definitions (also in the result's ``definitions``):

* error: the angle between the reported direction and pvlib's apparent sun direction (ENU);
* visibility of the sun (renderer's truth): ``visible`` if the beam transmittance of the
  clouds on its line of sight is >= 0.9, ``hidden`` if its saturated glare would be under
  0.5 deg in radius (a sun not discernible) or it is below the terrain, ``dimmed`` between;
* correct detection: found, within 1 deg, sun not hidden; false detection: found more than
  1 deg from the sun, or found while it is hidden; miss: not found while the sun is
  visible; correct rejection: not found while it is hidden; a dimmed sun not found is
  neither (it is not "clearly visible").
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime

import numpy as np

from .angular_error import error_stats

DEFINITIONS = {
    "error": "angle between the reported direction and pvlib SPA's apparent sun direction (ENU)",
    "visible": "cloud beam transmittance on the sun's line of sight >= 0.9",
    "hidden": "the sun's saturated glare under 0.5 deg in radius (not discernible), or below the terrain",
    "dimmed": "in between (not found: neither a miss nor a rejection)",
    "correct_detection": "found, within 1 deg, sun not hidden",
    "false_detection": "found more than 1 deg from the sun, or found while it is hidden",
    "miss": "not found while the sun is visible",
    "correct_rejection": "not found while the sun is hidden",
}


def utc(y: int, m: int, d: int, h: int = 0, mi: int = 0) -> float:
    return datetime(y, m, d, h, mi, tzinfo=UTC).timestamp()


def truth_bundle(scn, *, site: bool = True, orientation: bool = True, camera=None):
    """The world's own lens and rotation as a bundle (the known-calibration case)."""
    from controller.calibration.camera import CameraCal
    from controller.calibration.fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3

    L = scn.lens
    cam = camera or CameraCal(
        width=L.width, height=L.height, fx=L.fx, fy=L.fy, cx=L.cx, cy=L.cy, dist=tuple(L.D), model="fisheye"
    )
    s = scn.site
    return FisheyeBundle(
        camera=cam,
        orientation=OrientationCal(enu_from_camera=as_mat3(scn.R_enu_from_cam)) if orientation else None,
        site=SiteCal(latitude=s.latitude, longitude=s.longitude, altitude=s.altitude) if site else None,
    )


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))


def result_error(res, truth: dict, lens=None) -> float:
    """Error (deg) of a result; with ``lens`` (and the truth's rotation), the seed's centroid
    read through that calibrated lens instead of the paper's hemisphere model."""
    from controller.sun.types import azel_to_enu

    if lens is not None:
        d, ok = lens.rays([res.centre_uv])
        if not ok[0]:
            return float("nan")
        return angle_deg(np.asarray(truth["enu_from_camera"]) @ d[0], truth["sun_enu"])
    return angle_deg(azel_to_enu(res.az_deg, res.el_deg), truth["sun_enu"])


stats = error_stats  # the fisheye benches' name for it


def day_frames(scn, day: tuple[int, int, int], step_min: int, min_el: float = 5.0):
    """(t, az, el) of a day's frames with the sun above ``min_el``."""
    t0 = utc(*day)
    ts = t0 + np.arange(0, 86400, step_min * 60)
    sp = scn.sun(ts)
    return [
        (float(t), float(a), float(e)) for t, a, e in zip(ts, sp["azimuth"], sp["elevation"]) if e >= min_el
    ]


@dataclass
class Tally:
    """Counts of the cloud and distractor suites, and the errors of correct detections."""

    counts: dict = field(
        default_factory=lambda: {
            k: 0
            for k in (
                "frames",
                "correct_detection",
                "false_detection",
                "miss",
                "correct_rejection",
                "dimmed_not_found",
                "visible",
                "hidden",
                "dimmed",
            )
        }
    )
    errors_visible: list = field(default_factory=list)
    sigma_ratios: list = field(default_factory=list)
    reasons: dict = field(default_factory=dict)

    def add(self, res, truth: dict) -> None:
        c = self.counts
        vis = truth["visibility"]
        c["frames"] += 1
        c[vis] += 1
        if res.found:
            err = result_error(res, truth)
            if vis == "hidden" or err > 1.0:
                c["false_detection"] += 1
            else:
                c["correct_detection"] += 1
                if vis == "visible":
                    self.errors_visible.append(err)
                    self.sigma_ratios.append(err / max(float(res.sigma_deg or 1.0), 1e-9))
        elif vis == "visible":
            c["miss"] += 1
            self.reasons[res.reason] = self.reasons.get(res.reason, 0) + 1
        elif vis == "hidden":
            c["correct_rejection"] += 1
        else:
            c["dimmed_not_found"] += 1

    def summary(self) -> dict:
        c = dict(self.counts)
        c["miss_rate_of_visible"] = round(c["miss"] / max(c["visible"], 1), 4)
        r = np.asarray(self.sigma_ratios)
        return {
            "counts": c,
            "error_where_visible": stats(self.errors_visible),
            "frac_within_2sigma": round(float(np.mean(r < 2.0)), 3) if r.size else None,
            "miss_reasons": dict(sorted(self.reasons.items())),
        }


def run_sequences(sequences, make_estimators: dict) -> dict:
    """Score each estimator over sequences ``[(scene, [(t, render kwargs), ...]), ...]``; one
    fresh estimator per sequence (its rule 3 works within the sequence)."""
    from hil.skycam import render_sky

    tallies = {k: Tally() for k in make_estimators}
    for scn, frames in sequences:
        ests = {k: f(scn) for k, f in make_estimators.items()}
        rng = np.random.default_rng(int(frames[0][0]) & 0xFFFF)
        for t, kw in frames:
            fr = render_sky(scn, t, rng=rng, **kw)
            for k, est in ests.items():
                tallies[k].add(est.estimate_image(fr.image, t), fr.truth)
    return {k: v.summary() for k, v in tallies.items()}


def cloud_sequences(base, quick: bool):
    """Broken cumulus drifting over the camera: sequences of frames 60 s apart."""
    from hil.skycam import CloudField

    rng = np.random.default_rng(2024)
    coverages = (0.3, 0.45, 0.6)
    n_seq = 2 if quick else 5
    n_frames = 10 if quick else 30
    out: list = []
    for cov in coverages:
        for k in range(n_seq):
            day = [(2025, 3, 20), (2025, 6, 21), (2025, 9, 22), (2025, 12, 21)][k % 4]
            frames = day_frames(base, day, 10, min_el=15.0)
            t0 = frames[int(rng.integers(0, max(len(frames) - 4, 1)))][0]
            wx, wy = (float(x) for x in rng.uniform(-10, 10, 2))
            clouds = CloudField(
                coverage=cov,
                seed=int(rng.integers(1, 10_000)),
                wind_mps=(wx, wy),
                tau_max=float(rng.uniform(6, 16)),
                scale_m=float(rng.uniform(600, 1500)),
            )
            out.append((base.with_(clouds=clouds), [(t0 + 60.0 * i, {}) for i in range(n_frames)]))
    return out


def distractor_sequences(base, quick: bool):
    """A sun-sized reflection, an aircraft glint or a lens-flare ghost; in the middle third of
    each sequence a cloud hides the sun (the reflection and the glint stay lit)."""
    from hil.skycam import AircraftGlint, FlareGhost, SpecularReflection

    rng = np.random.default_rng(77)
    n_seq = 2 if quick else 6
    n_frames = 12 if quick else 30
    out: list = []
    for kind in ("reflection", "glint", "ghost"):
        for k in range(n_seq):
            day = [(2025, 3, 20), (2025, 6, 21), (2025, 12, 21)][k % 3]
            frames = day_frames(base, day, 10, min_el=15.0)
            t0 = frames[int(rng.integers(0, max(len(frames) - 5, 1)))][0]
            sun = base.sun([t0])
            dis: SpecularReflection | AircraftGlint | FlareGhost
            if kind == "reflection":
                dis = SpecularReflection(
                    az_deg=float((sun["azimuth"][0] + rng.uniform(40, 320)) % 360),
                    el_deg=float(rng.uniform(-8, 45)),
                    strength=float(rng.uniform(0.6, 1.0)),
                )
            elif kind == "glint":
                dis = AircraftGlint(
                    az0_deg=float(rng.uniform(0, 360)),
                    el0_deg=float(rng.uniform(20, 70)),
                    t0=t0,
                    daz_dps=float(rng.uniform(-0.08, 0.08)),
                    del_dps=float(rng.uniform(-0.02, 0.02)),
                    radius_px=float(rng.uniform(1.0, 3.0)) * base.lens.width / 640,
                    duration_s=n_frames * 60.0,
                )
            else:
                dis = FlareGhost(
                    position=float(rng.uniform(0.4, 1.0)),
                    radius_px=float(rng.uniform(6, 11)) * base.lens.width / 640,
                    level=float(rng.uniform(1.1, 1.8)),
                    tint=(
                        float(rng.uniform(0.7, 1.0)),
                        float(rng.uniform(0.7, 1.0)),
                        float(rng.uniform(0.7, 1.0)),
                    ),
                )
            scn = base.with_(distractors=(dis,))
            hide = range(n_frames // 3, 2 * n_frames // 3)
            out.append(
                (
                    scn,
                    [
                        (t0 + 60.0 * i, {"sun_transmittance": 0.0} if i in hide else {})
                        for i in range(n_frames)
                    ],
                )
            )
    return out


def variations(base):
    """Other looks of the world: lens, glare profile, smear, sky, compression."""
    from hil.skycam import FisheyeLens, orientation

    g, sen, sky = base.glare, base.sensor, base.sky
    other_lens = FisheyeLens(
        width=640,
        height=480,
        fx=150.0,
        fy=151.0,
        cx=322.4,
        cy=236.8,
        D=(-0.015, -0.004, 0.0008, -0.0001),
        fov_deg=200.0,
        name="other",
    )
    return {
        "nominal": base,
        "glare round on the sky (image_weight 0)": base.with_(glare=replace(g, image_weight=0.0)),
        "glare round on the sensor (image_weight 1)": base.with_(glare=replace(g, image_weight=1.0)),
        "narrow glare (radius 2 deg, power 4)": base.with_(glare=replace(g, radius_deg=2.0, power=4.0)),
        "wide soft glare (radius 5 deg, power 2, halo 0.3)": base.with_(
            glare=replace(g, radius_deg=5.0, power=2.0, halo_level=0.3)
        ),
        "CCD smear 0.3": base.with_(glare=replace(g, smear="ccd", smear_level=0.3)),
        "bloom 2 radii": base.with_(glare=replace(g, smear="bloom", smear_level=2.0)),
        "bright auto-exposed sky": base.with_(sensor=replace(sen, auto_exposure=True)),
        "JPEG q75": base.with_(sensor=replace(sen, jpeg_quality=75)),
        "lossless": base.with_(sensor=replace(sen, jpeg_quality=None)),
        "other lens (200 deg, fx 150)": base.with_(lens=other_lens),
        "tilted 6 deg": base.with_(
            enu_from_camera=orientation(yaw_deg=-40.0, tilt_deg=6.0, tilt_azimuth_deg=200.0)
        ),
        "hazy horizon (terrain 1 deg, brighter ground)": base.with_(
            sky=replace(sky, terrain_deg=1.0, ground_level=0.35)
        ),
    }


def frames_per_second(make_estimator, images, times, repeats: int = 5) -> dict:
    """Best of ``repeats`` passes over ``images`` taken at POSIX ``times`` (one core: OpenCV
    single-threaded); ``found``: the suns the last pass accepted (the frames' own times, so
    that the ephemeris gate passes them as in the field)."""
    return frames_per_second_interleaved({"": (make_estimator, images, times)}, repeats)[""]


def frames_per_second_interleaved(runs: dict, repeats: int) -> dict:
    """:func:`frames_per_second` of several ``runs`` (name -> (make_estimator, images,
    times)), their passes taken in turn, ``repeats`` rounds: each run's best pass comes from
    the same stretch of time.  A shared machine's speed swings by a quarter over minutes;
    timed one after the other, a run that fell in a slow stretch read slow for all its
    passes."""
    import cv2

    cv2.setNumThreads(1)
    ests = {}
    for name, (make, images, times) in runs.items():
        ests[name] = make()
        for img, t in zip(images[:3], times[:3]):
            ests[name].estimate_image(img, t)
    best = {name: float("inf") for name in runs}
    found = {name: 0 for name in runs}
    names = list(runs)
    for k in range(repeats):
        for name in names[k % len(names) :] + names[: k % len(names)]:  # each run leads in turn
            _, images, times = runs[name]
            est = ests[name]
            est.reset_sequence()
            start = time.perf_counter()
            res = [est.estimate_image(img, t) for img, t in zip(images, times)]
            best[name] = min(best[name], (time.perf_counter() - start) / len(images))
            found[name] = sum(bool(r.found) for r in res)
    return {
        name: {
            "ms_per_frame": round(1000 * best[name], 3),
            "fps": round(1.0 / best[name], 1),
            "frames": len(runs[name][1]),
            "found": found[name],
            "repeats": repeats,
        }
        for name in runs
    }


class SeedThroughLens:
    """The paper's detection (segmentation, rules, centroid), its centroid read through the
    calibrated lens and the bundle's rotation instead of the paper's hemisphere model: the
    seed's detection quality apart from its projection model."""

    def __init__(self, bundle):
        from controller.vision.fisheye import FisheyeLens, SeedEstimator

        self.inner = SeedEstimator(bundle)
        self.lens = FisheyeLens.from_camera(bundle.camera)
        self.R = bundle.enu_from_camera

    def reset_sequence(self) -> None:
        self.inner.reset_sequence()

    def estimate_image(self, image, t=None, prior=None):
        from controller.sun.types import enu_to_azel

        res = self.inner.estimate_image(image, t, prior)
        if res.found and res.centre_uv is not None:
            d, ok = self.lens.rays([res.centre_uv])
            if ok[0]:
                v = self.R @ d[0] if self.R is not None else d[0]
                az, el = enu_to_azel(v)
                res.az_deg, res.el_deg, res.d_cam = float(az), float(el), d[0]
        return res
