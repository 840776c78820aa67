"""Broken cloud and distractors drawn by the third renderer (:mod:`benchmarks.fisheye_third`):
the default pipeline's safety and accuracy away from the clear sky, on a renderer it was
not developed on.  The cloud and distractor model was written from a physical description
alone (not from ``hil.skycam`` or :mod:`benchmarks.fisheye_other`); the scene under it (the
Perez sky and its aureole, the Moffat glare, the lens, Santiago, the dark exposure look at
640 x 480, zenith grey 20, linear) is the third renderer's, imported.

* **cloud layer**: horizontal, 2 km up, a field of 2-D Gaussian puffs of optical depth
  (sigma 200-1500 m, peak 1-15) on a periodic 100 km tile; their number sets the coverage
  (a Poisson boolean model on the puffs' ``tau > 0.5`` footprints), drawn once per sequence
  from a seeded Generator; the field drifts with a wind of 5-12 m/s.  A pixel's ray meets
  the layer ``h / sin(el)`` away (under 3 deg: at 3 deg).
* **radiance**: the sky behind times ``exp(-tau)`` plus the cloud's own light
  ``(1 - exp(-tau)) grey (1 + F w(tau))``: ``grey`` a neutral 0.6-0.9 of the zenith sky's
  luminance-weighted level, ``F`` a Henyey-Greenstein phase (g = 0.8) of the angle to the sun,
  :data:`FORWARD_3DEG` at 3 deg (a ``tau`` ~ 1 edge there exceeds full scale: the silver
  lining), ``w`` 1 up to ``tau`` = 1 and ``tau exp(1 - tau)`` beyond (a thick cloud washes
  it out).  The glare, its smear and the aureole are scaled by the sun's own transmittance
  ``T = exp(-tau_sun)``; the smear lies on the columns the dimmed glare still saturates.
* **distractors**: a sun-glare-sized saturated reflection fixed on the ground 5 deg below
  the horizon (a window), aircraft glints (saturated 0.3 deg, 0.5 deg/s, 3 minutes each),
  a faint coloured lens-flare ghost mirrored through the principal point from the sun
  (scaled by ``T``).  The reflection and the glints stay lit when a cloud hides the sun.

Truth per frame: pvlib's apparent sun; ``visible`` if ``T >= 0.9``, ``hidden`` if the dimmed
glare alone saturates a disk under 0.5 deg in radius (the sun is then not discernible: the
convention of :mod:`benchmarks.fisheye_suites` and ``hil.skycam``; this glare peaks at ~400
times full scale, so it still saturates 0.8-1 deg at ``T`` = 0.04) or the sun is under 3 deg,
``dimmed`` between.  Scoring: :class:`benchmarks.fisheye_suites.Tally`
(a dimmed sun not found is neither a miss nor a rejection; found within 1 deg it is a
correct detection but its error is not in the visible RMS).

Passes: the renderer's own bundle with its ``[site]`` and without it; a camera calibrated as
an installer does on the clear :data:`CALIBRATION_DAY` (its rotation and sky calibration), too.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from datetime import UTC, datetime

import cv2
import numpy as np

from .fisheye_suites import DEFINITIONS, Tally, angle_deg
from .fisheye_third import (
    GLARE_BETA,
    LOOKS,
    SITE,
    SMEAR,
    ThirdScene,
    bundle_dict,
    perez_gradation,
    perez_indicatrix,
    sky_colour,
    sky_luminance,
    sun_enu,
    sun_frames,
)

DESCRIPTION = "fisheye sky camera on the third renderer: broken cloud (silver linings) and distractors"

LOOK = LOOKS[0]  # dark exposure, 640 x 480, zenith grey 20, linear
LAYER_M = 2000.0
MIN_RAY_EL = math.radians(3.0)
TILE_M, CELL_M = 100_000.0, 50.0  # the periodic cloud tile and its grid
SIGMA_M, PEAK_TAU = (200.0, 1500.0), (1.0, 15.0)
COVER_TAU = 0.5  # a point is under cloud where tau exceeds this
WIND_MPS = (5.0, 12.0)
GREY = (0.6, 0.9)  # the cloud's grey, of the zenith sky's luminance-weighted level
HG_G = 0.8
FORWARD_3DEG = 30.0  # the forward term 3 deg from the sun: a tau-1 edge there, 0.9-1.3 full scale
LUMA = np.array([0.2126, 0.7152, 0.0722])
VISIBLE_T, HIDDEN_T, MIN_SUN_EL = 0.9, 0.05, 3.0
HIDDEN_GLARE_DEG = 0.5  # a sun whose dimmed glare saturates less than this is hidden
REFLECTION_AZ_EL = (200.0, -5.0)  # where the lens sees furthest below the horizon
GLINT_DEG, GLINT_DPS, GLINT_S, GLINT_EVERY_S = 0.3, 0.5, 180.0, 1800.0
GHOST_DEG, GHOST_LEVEL, GHOST_RGB = 3.0, 0.35, np.array([0.45, 1.0, 0.6])
START_EL, SPAN_H = 12.0, 2.0  # a morning starts, an afternoon ends, with the sun this high
CLEAR_EVERY = 10  # the clear-sky reference: every tenth frame, the clouds and distractors off


@dataclass(frozen=True)
class Sequence:
    """One sequence: a local morning or afternoon, its cloud cover, whether it has the
    distractors, and the seed of everything random in it."""

    name: str
    day: str
    part: str  # "morning" or "afternoon"
    coverage: float
    seed: int
    distractors: bool = False


SEQUENCES = (
    Sequence("broken cloud 0.3, Dec 21 morning", "2026-12-21", "morning", 0.3, 31),
    Sequence("broken cloud 0.5, Mar 20 afternoon", "2026-03-20", "afternoon", 0.5, 52),
    Sequence("broken cloud 0.7, Dec 21 afternoon", "2026-12-21", "afternoon", 0.7, 73),
    Sequence("distractors, light cloud 0.15, Mar 20 morning", "2026-03-20", "morning", 0.15, 94, True),
)


# ---------------------------------------------------------------- clouds
class CloudLayer:
    """Gaussian puffs of optical depth on a periodic tile, drifting with the wind.

    Parameters
    ----------
    puffs : array-like, shape (n, 4)
        ``x, y`` (m, East and North of the camera at ``t0``), ``sigma`` (m), peak ``tau``.
    wind_mps : (east, north), m/s
    grey : float
        The cloud's grey, of the zenith sky's luminance-weighted level.
    t0 : float
        POSIX seconds at which the puffs stand where given.
    """

    def __init__(self, puffs, wind_mps, grey: float, t0: float):
        self.puffs = np.asarray(puffs, float).reshape(-1, 4)
        self.wind = np.asarray(wind_mps, float)
        self.grey, self.t0 = float(grey), float(t0)
        n = self.n = int(round(TILE_M / CELL_M))
        grid = np.zeros((n, n), np.float32)
        for x, y, sg, peak in self.puffs:
            half = int(math.ceil(4 * sg / CELL_M))
            ix = round(x / CELL_M) + np.arange(-half, half + 1)
            iy = round(y / CELL_M) + np.arange(-half, half + 1)
            dx2, dy2 = (ix * CELL_M - x) ** 2, (iy * CELL_M - y) ** 2
            blob = peak * np.exp(-(dy2[:, None] + dx2[None, :]) / (2 * sg * sg))
            grid[np.ix_(iy % n, ix % n)] += blob.astype(np.float32)
        self.grid = grid

    @classmethod
    def random(cls, coverage: float, rng: np.random.Generator, t0: float) -> CloudLayer:
        """Puffs drawn until their footprints (``tau > COVER_TAU``) add up to the area a
        Poisson boolean model needs for ``coverage``; a random wind and grey."""
        need, area, puffs = -math.log(1 - coverage) * TILE_M**2, 0.0, []
        while area < need:
            sg, peak = rng.uniform(*SIGMA_M), rng.uniform(*PEAK_TAU)
            puffs.append((*rng.uniform(0, TILE_M, 2), sg, peak))
            area += 2 * math.pi * sg * sg * math.log(max(peak / COVER_TAU, 1.0))
        speed, heading = rng.uniform(*WIND_MPS), rng.uniform(0, 2 * math.pi)
        wind = (speed * math.sin(heading), speed * math.cos(heading))
        return cls(puffs, wind, rng.uniform(*GREY), t0)

    def coverage(self) -> float:
        """The tile's fraction under cloud (``tau > COVER_TAU``)."""
        return float((self.grid > COVER_TAU).mean())

    def tau(self, xy, t: float) -> np.ndarray:
        """Optical depth at points ``xy`` (..., 2) (m, East and North of the camera) at
        time ``t``: the grid read bilinearly, periodic, the field moved by the wind."""
        g = (np.asarray(xy, float) - self.wind * (t - self.t0)) / CELL_M % self.n
        i0 = np.floor(g).astype(int)
        f = g - i0
        i1 = (i0 + 1) % self.n
        x0, y0, x1, y1 = i0[..., 0], i0[..., 1], i1[..., 0], i1[..., 1]
        fx, fy = f[..., 0], f[..., 1]
        top = self.grid[y0, x0] * (1 - fx) + self.grid[y0, x1] * fx
        return top * (1 - fy) + (self.grid[y1, x0] * (1 - fx) + self.grid[y1, x1] * fx) * fy


def layer_xy(d_enu) -> np.ndarray:
    """Where rays ``d_enu`` (..., 3) meet the layer (m, East and North of the camera):
    ``h / tan(el)`` out along their azimuth, the elevation at least 3 deg."""
    d = np.asarray(d_enu, float)
    horiz = np.hypot(d[..., 0], d[..., 1])
    el = np.maximum(np.arctan2(d[..., 2], horiz), MIN_RAY_EL)
    k = LAYER_M / np.tan(el) / np.maximum(horiz, 1e-12)
    return d[..., :2] * k[..., None]


def forward(gamma) -> np.ndarray:
    """The cloud's forward scattering at ``gamma`` (rad) from the sun: a Henyey-Greenstein
    phase (g = :data:`HG_G`) scaled to :data:`FORWARD_3DEG` at 3 deg."""

    def hg(c):
        return (1 - HG_G**2) / (1 + HG_G**2 - 2 * HG_G * c) ** 1.5

    return FORWARD_3DEG * hg(np.cos(gamma)) / hg(math.cos(math.radians(3.0)))


def cloud_light(tau, gamma, grey_fs: float) -> np.ndarray:
    """The cloud's own light (full scale): ``(1 - exp(-tau)) grey (1 + F w(tau))``, ``w`` 1 up
    to ``tau`` = 1 and ``tau exp(1 - tau)`` beyond; ``grey_fs`` in full-scale units."""
    tau = np.asarray(tau, float)
    wash = np.where(tau <= 1.0, 1.0, tau * np.exp(1.0 - tau))
    return (1 - np.exp(-tau)) * grey_fs * (1 + forward(gamma) * wash)


# ---------------------------------------------------------------- distractors
@dataclass(frozen=True)
class Glint:
    """An aircraft's glint: along a great circle at ``GLINT_DPS`` for ``GLINT_S`` from ``t_on``."""

    t_on: float
    start: tuple[float, float, float]  # ENU unit vector
    axis: tuple[float, float, float]  # the great circle's pole (unit)

    def direction(self, t: float) -> np.ndarray | None:
        """Its ENU direction at ``t``, None when it is not there."""
        dt = t - self.t_on
        if not 0.0 <= dt <= GLINT_S:
            return None
        rot = cv2.Rodrigues(np.radians(GLINT_DPS * dt) * np.asarray(self.axis))[0]
        return rot @ np.asarray(self.start)


def random_glints(t0: float, t1: float, rng: np.random.Generator) -> tuple[Glint, ...]:
    """One aircraft every :data:`GLINT_EVERY_S`: a track whose middle is 45-75 deg up."""
    out = []
    for t_on in np.arange(t0 + 0.3 * GLINT_EVERY_S, t1 - GLINT_S, GLINT_EVERY_S):
        mid = sun_enu(rng.uniform(0, 360), rng.uniform(45, 75))
        tangent = np.cross(mid, sun_enu(rng.uniform(0, 360), 0.0))
        axis = np.cross(mid, tangent / np.linalg.norm(tangent))
        back = cv2.Rodrigues(-np.radians(GLINT_DPS * GLINT_S / 2) * axis)[0]
        out.append(Glint(float(t_on), tuple(back @ mid), tuple(axis)))
    return tuple(out)


# ---------------------------------------------------------------- the renderer
class CloudyScene(ThirdScene):
    """The third renderer's scene under a :class:`CloudLayer`, with or without distractors.
    :meth:`frame` draws one frame and its truth."""

    def __init__(self, look=LOOK):
        super().__init__(look)
        self.xy = layer_xy(self.d_enu)
        self.clouds: CloudLayer | None = None
        self.glints: tuple[Glint, ...] = ()
        self.with_distractors = False
        self.seed, self.t, self.glare_sat_deg = 0, 0.0, 0.0

    def set_sequence(self, clouds: CloudLayer | None, glints=(), distractors=False, seed=0) -> None:
        """The sequence's clouds (None: a clear sky), its aircraft, whether the reflection
        and the ghost are drawn, and the seed of its frames' noise."""
        self.clouds, self.glints, self.with_distractors, self.seed = clouds, tuple(glints), distractors, seed

    def tau_px(self, t: float) -> np.ndarray:
        """Optical depth on each pixel's ray (H, W); 0 without clouds."""
        if self.clouds is None:
            return np.zeros(self.u.shape)
        return self.clouds.tau(self.xy, t)

    def transmittance(self, s_enu, t: float) -> float:
        """``exp(-tau)`` on the sun's line of sight."""
        if self.clouds is None:
            return 1.0
        return float(np.exp(-self.clouds.tau(layer_xy(s_enu), t)))

    def truth(self, t: float, az: float, el: float, glare_sat_deg: float | None = None) -> dict:
        """The sun's label: hidden when its dimmed glare saturates under
        :data:`HIDDEN_GLARE_DEG` (``glare_sat_deg``, deg, from the render; without it, when
        ``T`` < :data:`HIDDEN_T`) or it is under :data:`MIN_SUN_EL`."""
        s = sun_enu(az, el)
        T = self.transmittance(s, t)
        dark = T < HIDDEN_T if glare_sat_deg is None else glare_sat_deg < HIDDEN_GLARE_DEG
        label = "hidden" if dark or el < MIN_SUN_EL else "visible" if T >= VISIBLE_T else "dimmed"
        return {"visibility": label, "sun_enu": s, "transmittance": T, "az_deg": az, "el_deg": el}

    def frame(self, t: float, az: float, el: float) -> tuple[np.ndarray, dict]:
        """The frame at ``t`` with the sun at ``(az, el)``: its BGR uint8 image (noise seeded
        by the sequence and ``t``) and its truth."""
        self.t = t
        img = self.render(sun_enu(az, el), np.random.default_rng([self.seed, int(t)]))
        return img, dict(self.truth(t, az, el, self.glare_sat_deg), glare_sat_deg=self.glare_sat_deg)

    def render_linear(self, s_enu: np.ndarray) -> np.ndarray:
        """The light on the sensor at time ``self.t`` (H, W, 3; linear RGB, full scale 1)."""
        t, sky = self.t, self.sky
        T = self.transmittance(s_enu, t)
        gamma = np.arccos(np.clip(self.d_enu @ s_enu, -1, 1))
        clear = self.gradation * perez_indicatrix(gamma)
        aureole = sky_luminance(gamma, self.gradation) - clear
        # exposure: the clear zenith sky's mean R, G, B at zenith_grey / 255
        gz = np.array(math.acos(float(np.clip(s_enu[2], -1, 1))))
        zenith = sky_colour(np.asarray(sky_luminance(gz, perez_gradation(1.0))), gz)
        expo = self.look.zenith_grey / 255.0 / float(zenith.mean())
        tau = self.tau_px(t)
        behind = sky_colour(clear + T * aureole, gamma) * (expo * np.exp(-tau))[..., None]
        own = cloud_light(tau, gamma, self.clouds.grey * expo * float(zenith @ LUMA)) if self.clouds else 0.0
        img = np.where(sky[..., None], behind + np.asarray(own)[..., None], 0.0)
        img[self.ground] = self.ground_rgb[self.ground]
        glare = T * self.glare(s_enu)
        img += glare[..., None]
        # the radius of the disk the dimmed glare alone saturates (deg; 0: none)
        self.glare_sat_deg = math.sqrt(float((glare >= 1.0).sum()) / math.pi) / self.lens.px_per_deg
        img[:, glare.max(axis=0) >= 1.0, :] += SMEAR * T
        img += self.distractors(s_enu, T, t)
        return img

    def distractors(self, s_enu, T: float, t: float) -> np.ndarray:
        """The reflection, the glint and the ghost at ``t`` (H, W, 3), linear; 0 without them."""
        out = np.zeros(self.u.shape + (3,))
        if not self.with_distractors:
            return out
        out += self.glare(sun_enu(*REFLECTION_AZ_EL))[..., None]
        ppd = self.lens.px_per_deg
        for g in self.glints:
            d = g.direction(t)
            if d is not None:
                gu, gv = self.sun_uv(d)
                r = np.hypot(self.u - gu, self.v - gv) / ppd
                a = GLINT_DEG / math.sqrt(3.0 ** (1 / GLARE_BETA) - 1)  # 3 x full scale at the centre
                out += (3.0 * (1 + (r / a) ** 2) ** -GLARE_BETA * self.inside)[..., None]
        us, vs = self.sun_uv(s_enu)
        r = np.hypot(self.u - (2 * self.lens.cx - us), self.v - (2 * self.lens.cy - vs)) / ppd
        disk = np.clip(GHOST_DEG - r + 0.5, 0.0, 1.0) * self.inside
        return out + (T * GHOST_LEVEL * disk)[..., None] * GHOST_RGB


# ---------------------------------------------------------------- sequences and scoring
def frame_times(seq: Sequence, hours: float, step_s: float) -> list[tuple[float, float, float]]:
    """``(t, az, el)`` of a sequence's frames over its first ``hours``: a :data:`SPAN_H`
    morning from the sun at :data:`START_EL` up, or afternoon down to it (a quick run's
    frames are a full run's); pvlib's NREL SPA azimuth and apparent elevation."""
    import pandas as pd
    import pvlib

    up = [t for t, _, el in sun_frames(seq.day, 1) if el >= START_EL]
    t0 = up[0] if seq.part == "morning" else up[-1] - SPAN_H * 3600.0
    ts = t0 + step_s * np.arange(int(round(hours * 3600.0 / step_s)))
    sp = pvlib.solarposition.get_solarposition(
        pd.to_datetime(ts, unit="s", utc=True), SITE[0], SITE[1], SITE[2], method="nrel_numpy"
    )
    return [(float(t), float(a), float(e)) for t, a, e in zip(ts, sp["azimuth"], sp["apparent_elevation"])]


def set_up(scene: CloudyScene, seq: Sequence, t0: float, t1: float) -> dict:
    """Draw the sequence's clouds (and distractors) into ``scene``; return their parameters."""
    rng = np.random.default_rng(seq.seed)
    clouds = CloudLayer.random(seq.coverage, rng, t0)
    glints = random_glints(t0, t1, rng) if seq.distractors else ()
    scene.set_sequence(clouds, glints, seq.distractors, seq.seed)
    return {
        "name": seq.name,
        "day": seq.day,
        "start_utc": utc(t0),
        "coverage_target": seq.coverage,
        "coverage_drawn": round(clouds.coverage(), 3),
        "puffs": len(clouds.puffs),
        "wind_mps": [round(float(w), 2) for w in clouds.wind],
        "grey": round(clouds.grey, 3),
        "distractors": ["reflection", f"{len(glints)} aircraft glints", "ghost"] if seq.distractors else [],
    }


def utc(t: float) -> str:
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="seconds")


class Scorer:
    """One pass's :class:`Tally` per sequence and in total, and its false detections and
    misses as cases to look at."""

    def __init__(self):
        self.total, self.per_seq, self.cases, self.on_hidden_sun = Tally(), {}, [], 0

    def add(self, seq: str, t: float, res, truth: dict) -> None:
        before = dict(self.total.counts)
        for tally in (self.per_seq.setdefault(seq, Tally()), self.total):
            tally.add(res, truth)
        kind = next((k for k in ("false_detection", "miss") if self.total.counts[k] > before[k]), None)
        if kind is None:
            return
        case = {
            "kind": kind,
            "sequence": seq,
            "t": t,
            "utc": utc(t),
            "label": truth["visibility"],
            "transmittance": round(truth["transmittance"], 4),
            "sun_az_el": [round(truth["az_deg"], 3), round(truth["el_deg"], 3)],
            "glare_sat_deg": round(truth.get("glare_sat_deg", math.nan), 2),
        }
        if res.found:
            err = angle_deg(sun_enu(res.az_deg, res.el_deg), truth["sun_enu"])
            case.update(found_az_el=[round(float(res.az_deg), 3), round(float(res.el_deg), 3)], error_deg=err)
            self.on_hidden_sun += int(err <= 1.0)  # false only for being hidden
        else:
            case["reason"] = str(res.reason)
        self.cases.append(case)

    def summary(self) -> dict:
        total = self.total.summary()
        c, rms = total["counts"], total["error_where_visible"].get("rms_deg")
        return {
            "per_sequence": {k: v.summary() for k, v in self.per_seq.items()},
            "total": total,
            "false_detections_on_a_hidden_sun": self.on_hidden_sun,
            "acceptance": {
                "zero_false_detections": c["false_detection"] == 0,
                "misses_le_5pct": c["miss_rate_of_visible"] <= 0.05,
                "visible_rms_le_0.2": rms is not None and rms <= 0.2,
            },
        }


PASSES = ("with site", "without site")
#: the clear day a camera is calibrated on for the calibrated passes (the third renderer's)
CALIBRATION_DAY = "2026-03-20"


def bundles() -> dict:
    """The bundle with its ``[site]`` (the ephemeris gate on) and without it."""
    full = bundle_dict(LOOK)
    return {"with site": full, "without site": {k: v for k, v in full.items() if k != "site"}}


def calibrated_bundles(day: str = CALIBRATION_DAY) -> tuple[dict, dict]:
    """A camera calibrated on the renderer's clear ``day`` as an installer does
    (:func:`benchmarks.fisheye_selfcal.calibrated_third`), with its site and without it (by
    pass name), and what the calibration wrote."""
    from dataclasses import replace

    from .fisheye_selfcal import calibrated_third

    cal, wrote = calibrated_third(LOOKS.index(LOOK), day)
    return {"calibrated, with site": cal, "calibrated, without site": replace(cal, site=None)}, wrote


def run_sequences(seqs, hours: float, step_s: float, calibrated: dict | None = None) -> dict:
    """Render the sequences and score the default pipeline on them, each pass its own
    estimator, reset between sequences (``calibrated``: more passes, by name, with their
    :class:`FisheyeBundle`)."""
    from controller.calibration.fisheye_bundle import fisheye_bundle_from_dict
    from controller.vision.fisheye import FisheyeEstimator

    ests = {k: FisheyeEstimator(fisheye_bundle_from_dict(b)) for k, b in bundles().items()}
    ests.update({k: FisheyeEstimator(b) for k, b in (calibrated or {}).items()})
    scorers = {k: Scorer() for k in ests}
    clear = {k: Scorer() for k in ests}
    scene, drawn = CloudyScene(), []
    for seq in seqs:
        frames = frame_times(seq, hours, step_s)
        info = set_up(scene, seq, frames[0][0], frames[-1][0])
        info["frames"], info["sun_el_range"] = len(frames), [round(frames[0][2], 1), round(frames[-1][2], 1)]
        drawn.append(info)
        for key, todo in (("clouds", frames), ("clear", frames[::CLEAR_EVERY])):
            if key == "clear":
                scene.set_sequence(None, seed=seq.seed)
            for est in ests.values():
                est.reset_sequence()
            for t, az, el in todo:
                img, truth = scene.frame(t, az, el)
                for k, est in ests.items():
                    (scorers if key == "clouds" else clear)[k].add(
                        seq.name, t, est.estimate_image(img, t), truth
                    )
    passes = {k: s.summary() for k, s in scorers.items()}
    for k, p in passes.items():
        p["clear_reference"] = clear[k].total.summary()
    return {
        "sequences": drawn,
        "passes": passes,
        "cases": [dict(c, **{"pass": k}) for k, s in scorers.items() for c in s.cases],
        "clear_reference_cases": [dict(c, **{"pass": k}) for k, s in clear.items() for c in s.cases],
    }


def run(quick: bool = False, calibrated: bool = True) -> dict:
    """The benchmark: four 2-hour sequences, a frame every 30 s, with and without the site,
    with the renderer's own bundle and (``calibrated``) with a camera calibrated on its clear
    :data:`CALIBRATION_DAY` (:func:`calibrated_bundles`).

    Parameters
    ----------
    quick : bool
        One sequence (coverage 0.5), 1 hour, a frame every 2 minutes.

    Returns
    -------
    dict
        ``sequences`` (what was drawn), ``passes`` (by pass: ``per_sequence`` and ``total``
        :meth:`Tally.summary`, ``acceptance``, and ``clear_reference``: every tenth frame
        with the clouds and distractors off, the renderer's clear-sky baseline at those
        times, not judged), ``cases`` (every false detection and miss; those of the clear
        reference apart), ``acceptance`` (every pass), ``calibration`` (what the calibrated
        passes' calibration wrote), ``definitions``, ``seconds``.
    """
    t0 = time.perf_counter()
    seqs = SEQUENCES[1:2] if quick else SEQUENCES
    hours, step_s = (1.0, 120.0) if quick else (2.0, 30.0)
    cal, wrote = calibrated_bundles() if calibrated else (None, None)
    out = run_sequences(seqs, hours, step_s, cal)
    if wrote is not None:
        out["calibration"] = wrote
    accs = [p["acceptance"] for p in out["passes"].values()]
    out["acceptance"] = {k: all(a[k] for a in accs) for k in accs[0]}
    out["definitions"] = dict(
        DEFINITIONS,
        visible=f"sun's beam transmittance exp(-tau_sun) >= {VISIBLE_T}",
        hidden=f"the dimmed glare saturates under {HIDDEN_GLARE_DEG:g} deg in radius, or the sun under {MIN_SUN_EL:g} deg",
    )
    out.update(hours=hours, step_s=step_s, seconds=round(time.perf_counter() - t0, 1))
    return out
