"""Where between the rim's fix and the rings' a camera's sun lies, learned as it runs.

The rim (:mod:`.glare`) and the sky's rings (:mod:`.rings`) each place the sun; which is
right depends on the camera's sky and glare, and no frame tells the two apart
(docs/fisheye-rounds.md, a twenty-fourth round).  With the bundle's site the ephemeris
weighs them: a weight by elevation between the two fixes, learned from the frames before
(:class:`LocatorChoice`).  Without it the sun's own path chooses one
(:meth:`LocatorChoice.observe_path`).  A cloud in the rings leaves only the rim; where the
rings weigh, its fix is then moved by that share of its offset from theirs at that
elevation, learned where both placed the sun (:meth:`LocatorChoice.rim_as_rings`).

Directions are unit vectors, in the camera frame unless named ENU.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from .rings import ring_direction

#: without the site, the rings are chosen once their squared RMS about their own site is
#: under this share of the rim's, the rim once its is under this share of theirs, and between
#: the two the choice stays open (:meth:`LocatorChoice.observe_path`); with it the weight
#: between the two is learned once this many frames have both fixes (:class:`LocatorChoice`)
LEAD, MIN_FRAMES = 0.5, 2
#: the weight is learned from the frames within BAND_DEG of the sun's elevation, at least
#: MIN_BAND of them; frames whose blended fix is farther from the sun than TRIM_K times the
#: median are left out (:func:`blend_weight`)
BAND_DEG, MIN_BAND, TRIM_K = 4.0, 4, 3.0
#: where fewer lie in the band (a low sun: a frame every 30 min sees two or three a day), from
#: every frame kept as a weight linear in the air mass less one, once AIRMASS_MIN_FRAMES are
#: kept (:func:`weight_by_airmass`); before that, one weight over them all
AIRMASS_MIN_FRAMES = 8
#: the weight before it is learned, for a camera whose calibration day did not choose (a
#: surveyed bundle, no ``locator``): halfway, the least that either fix can be wrong by
#: (a camera's second frame: the third renderer's rim 0.19 deg off, halfway 0.10-0.12; the
#: second renderer's rings 0.23 off, halfway 0.10)
UNKNOWN_PRIOR = 0.5
#: and the rings move its rim 0.1 deg at most (half the most a product sky's have moved a clear
#: rim); a lens's glare can put their fix 0.4 deg off (the HIL's bright sky: 0.19-0.21 halfway)
UNKNOWN_MAX_MOVE_DEG = 0.1
#: where the rings weigh but place no sun, the rim's fix is moved by (its weight of) its median
#: offset from the rings' on the frames both placed, the sun within this many degrees of
#: elevation of it (at least :data:`MIN_OFFSETS` of them; :meth:`LocatorChoice.place`), else
#: the MIN_OFFSETS nearest in elevation, within NEAREST_OFFSET_DEG of it
OFFSET_EL_DEG, MIN_OFFSETS, NEAREST_OFFSET_DEG = 2.0, 3, 8.0
#: a frame whose rim lies farther than this (deg) from where the camera's learned offset puts
#: it against the rings' fix has rings astray: they are then treated as placing no sun
OFFSET_ASTRAY_DEG = 0.5
#: without the site, the choice by the sun's own path (:meth:`LocatorChoice.observe_path`):
#: a sight of both fixes kept at most every PATH_STEP_S, for PATH_KEEP_S (s; 720 at most),
#: the sun PATH_MIN_EL_DEG high at least; the paths are compared once PATH_MIN_SIGHTS span
#: PATH_MIN_SPAN_S (s) and one of them is PATH_LOW_EL_DEG high at most, then at every sight
#: until a comparison chooses, and every PATH_EVERY sights after.  The span is what tells a sky
#: model's bend from a path; six sights (twelve numbers for a site's two) suffice, and at a
#: frame every few minutes the span binds; where frames are 20-30 min apart, twelve sights
#: had left a winter day's first half halfway between the fixes (the third renderer's clear
#: days without the site, a day a call: 0.0302 -> 0.0201 deg at 640 x 480).  A sky model's
#: error grows with the air mass: over sights all above 30 deg (air mass under 2) a rim it
#: barely moves fits its site best, and was chosen for the low sun where it is 0.2 deg off
#: (the third renderer at Quito, 21 Dec's afternoon read first as a batch's second half: the
#: rim 0.0115 deg about its site, the rings 0.0584, over six sights at 58-67 deg; 0.0549 ->
#: 0.0142 deg at 1280 x 960).  A comparison chooses only when its ratio is one that chance
#: leaves with probability PATH_SIGNIFICANCE at most (:func:`path_lead`), and under LEAD
PATH_STEP_S, PATH_KEEP_S, PATH_MIN_EL_DEG = 120.0, 172800.0, 12.0
PATH_MIN_SIGHTS, PATH_MIN_SPAN_S, PATH_EVERY = 6, 3600.0, 5
PATH_LOW_EL_DEG, PATH_SIGNIFICANCE = 30.0, 0.01


def path_lead(sights: int, significance: float = PATH_SIGNIFICANCE) -> float:
    """The share of one locator's squared RMS about its own site under which the other's
    chooses it, from ``sights`` sights: the ratio of two such sums of squares (two numbers a
    sight, two a site: ``2 sights - 2`` degrees of freedom each) that chance alone leaves
    under it with probability ``significance`` (0.21 for 6 sights, 0.34 for 11, 0.51 for 26).
    Six sights at 12-18 deg had chosen the rim of the third renderer at 70 N, its squared
    RMS 0.22 of the rings' (0.2 deg off until the sixteenth sight, 1280 x 960); six sights
    need 0.21.  The errors are a sky model's, not independent draws: the level is a guide."""
    from scipy.stats import f

    dof = max(2 * sights - 2, 1)
    return float(1.0 / f.ppf(1.0 - significance, dof, dof))


def blend_weight(rim: np.ndarray, rings: np.ndarray, trim_k: float = TRIM_K, rounds: int = 5) -> float:
    """The weight ``w`` in [0, 1] whose fixes ``rim + w (rings - rim)`` lie closest to the
    sun, by least squares; ``rim``, ``rings``: (n, 3) each fix less the sun's direction (ENU).
    Frames whose blended fix lies farther than ``trim_k`` times the median are left out and
    the weight refitted, ``rounds`` times at most: under broken cloud both fixes can be
    0.5-1 deg off, and those frames alone had set the weight (the third renderer's clouds:
    the clear reference after them 0.028 -> 0.066 deg untrimmed)."""
    c = _trimmed_weight(rim, rings, np.ones((len(rim), 1)), trim_k, rounds)
    return min(max(float(c[0]), 0.0), 1.0)


class AirmassWeight(NamedTuple):
    """A weight ``w0 + w1 x`` in the air mass less one, ``x = 1 / sin(el) - 1``, clipped to
    [0, 1]; ``x`` is held within the frames' own ``(x_lo, x_hi)``, so that frames all near
    one elevation, whose trend is loose, are not carried far beyond it."""

    w0: float
    w1: float
    x_lo: float
    x_hi: float

    def at(self, el_deg: float) -> float:
        """The weight for a sun ``el_deg`` (deg) high."""
        x = min(max(1.0 / math.sin(math.radians(max(el_deg, 1.0))) - 1.0, self.x_lo), self.x_hi)
        return min(max(self.w0 + self.w1 * x, 0.0), 1.0)


def weight_by_airmass(
    el_deg: np.ndarray, rim: np.ndarray, rings: np.ndarray, trim_k: float = TRIM_K, rounds: int = 5
) -> AirmassWeight:
    """The :class:`AirmassWeight` fitted as :func:`blend_weight` is, each frame at its sun's
    elevation ``el_deg`` (deg).  A sky's pull on the rim grows with the air mass towards the
    horizon, the rings' with the gradation's bend there: where the band of a low sun holds
    too few frames, the frames on either side carry the trend to it, and below the lowest
    the trend's weight there holds (:class:`AirmassWeight`; the second renderer's
    power-law aureole, whose suns at 5-11 deg one weight over all frames had read at 0.39:
    0.0324 -> 0.0224 deg RMS, the rim moved as :meth:`LocatorChoice.rim_as_rings` does)."""
    x = 1.0 / np.sin(np.radians(np.maximum(el_deg, 1.0))) - 1.0
    c = _trimmed_weight(rim, rings, np.column_stack([np.ones(len(x)), x]), trim_k, rounds)
    return AirmassWeight(float(c[0]), float(c[1]), float(x.min()), float(x.max()))


def _trimmed_weight(
    rim: np.ndarray, rings: np.ndarray, basis: np.ndarray, trim_k: float, rounds: int
) -> np.ndarray:
    """Coefficients ``c`` of the weights ``w_i = basis_i . c`` (clipped to [0, 1]) whose
    fixes ``rim_i + w_i (rings_i - rim_i)`` lie closest to the sun by least squares, the
    frames farther than ``trim_k`` times the median left out and refitted (:func:`blend_weight`)."""
    dg = rings - rim
    a, b = np.einsum("ij,ij->i", dg, dg), np.einsum("ij,ij->i", rim, dg)
    keep = np.ones(len(rim), bool)
    c = np.zeros(basis.shape[1])
    for _ in range(rounds):
        B = basis[keep]
        N, g = (B * a[keep, None]).T @ B, -(B * b[keep, None]).sum(axis=0)
        try:
            c = np.linalg.solve(N, g)
        except np.linalg.LinAlgError:  # all fixes alike, or all frames at one elevation
            c = np.linalg.lstsq(N, g, rcond=None)[0]
        w = np.clip(basis @ c, 0.0, 1.0)
        res = np.linalg.norm(rim + w[:, None] * dg, axis=1)
        new = res <= trim_k * float(np.median(res))
        if (new == keep).all() or not new.any():
            break
        keep = new
    return c


class LocatorChoice:
    """Where between the rim's fix and the rings' this camera's sun lies, learned from the
    ephemeris: a weight ``w`` (0 the rim, 1 the rings; :func:`blend_weight`) fitted to the
    frames before where both were measured within ``max_deg`` of the sun, those within
    :data:`BAND_DEG` of the frame's elevation.  A frame's fix is placed from the frames before
    it, so the ephemeris never picks a frame's own answer.  The weight is the camera's (its
    sky's, its glare's): it is kept across sequences.  A weight, not a choice, because the
    two can err on either side of the sun: the second renderer's wide glare reads 0.03-0.18
    deg low by the rim and 0.06-0.25 high by the rings (weight 0.18; 0.0461 -> 0.0397 deg),
    and the split changes with the elevation (its CIE sky 15: 0.0252 -> 0.0200 by the band's
    weight, 0.0248 by one weight for all); a sky that is a product reads right by the rings
    (the third renderer: 0.92-1.0).  Each frame where both placed the sun also keeps the
    rim's offset from the rings (:meth:`rim_as_rings`).
    """

    def __init__(
        self,
        window: int = 60,
        max_deg: float = 1.0,
        lead: float = LEAD,
        min_frames: int = MIN_FRAMES,
        settled: int = 20,
        every: int = 10,
        always: bool = False,
        prior: str | None = None,
    ):
        # each fix less the sun's direction (ENU) with the sun's elevation (deg), both measured
        self._err: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=4 * window)
        self._always = always  # the rings, wherever they place the sun (no choice learned)
        # the calibration day's choice (rings 1, rim 0; none: halfway) until frames have chosen
        self._prior = {"rings": 1.0, "rim": 0.0}.get(prior or "", UNKNOWN_PRIOR)
        self._unknown = prior not in ("rings", "rim") and not always  # no choice was made
        self._max, self._lead, self._min = max_deg, lead, min_frames
        self._settled, self._every, self._frames = settled, every, 0
        self._all_w: float | None = None  # the weight over every frame kept (until the next)
        self._airmass: AirmassWeight | None = None  # the same by the air mass
        # the rim's fix less the rings', along the vertical and across it (rad), by elevation (deg)
        self._offsets: deque[tuple[float, float, float]] = deque(maxlen=4 * window)
        # without the site: sights of both fixes (t, rim ENU, rings ENU), and the squared RMS
        # of a site fitted to each (rim, rings) once they span enough of the sun's path
        self._path: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=720)
        self._path_sq: tuple[float, float] | None = None
        self._path_choice: float | None = None  # the last comparison that told them apart: 1 rings, 0 rim
        self._path_new = 0

    @classmethod
    def of_camera(cls, gates: Any, orientation: Any) -> LocatorChoice | None:
        """The choice of a camera with ``gates`` (:class:`.gates.GateOptions`) and its bundle's
        ``orientation`` (its ``locator``, the calibration day's choice), or None when the
        gates leave the rim alone (``ring_locator`` off)."""
        if not gates.ring_locator:
            return None
        prior = None if orientation is None else orientation.locator
        return cls(always=gates.rings_always, prior=prior)

    def weight(self, el_deg: float | None = None) -> float:
        """The weight of the rings' fix (0 the rim's, 1 the rings'; :func:`blend_weight`) over
        the frames within :data:`BAND_DEG` of ``el_deg``; where they are fewer than
        :data:`MIN_BAND`, by the air mass over all kept (:func:`weight_by_airmass`, once
        :data:`AIRMASS_MIN_FRAMES` are kept), else (or ``el_deg`` None) one weight over all
        kept; before ``min_frames`` frames, as the calibration day chose (``prior``); always 1
        when so constructed (``always``)."""
        if self._always:
            return 1.0
        if len(self._err) < max(self._min, 1):
            return self._prior
        if el_deg is not None:
            near = [e for e in self._err if abs(e[0] - el_deg) <= BAND_DEG]
            if len(near) >= MIN_BAND:
                return blend_weight(np.array([e[1] for e in near]), np.array([e[2] for e in near]))
            if len(self._err) >= AIRMASS_MIN_FRAMES:
                if self._airmass is None:
                    err = self._err
                    self._airmass = weight_by_airmass(
                        np.array([e[0] for e in err]),
                        np.array([e[1] for e in err]),
                        np.array([e[2] for e in err]),
                    )
                return self._airmass.at(el_deg)
        if self._all_w is None:
            err = self._err
            self._all_w = blend_weight(np.array([e[1] for e in err]), np.array([e[2] for e in err]))
        return self._all_w

    @property
    def rings(self) -> bool:
        """True when the rings' fix weighs at least half over every frame kept
        (:meth:`weight`)."""
        return self.weight() >= 0.5

    @property
    def path_rings(self) -> bool:
        """Without the site: True when the rings' fix is taken (:meth:`path_weight` over half)."""
        return self.path_weight() > 0.5

    def path_weight(self) -> float:
        """Without the site, the weight of the rings' fix: 1 when a site fitted to the rings'
        sights left under ``lead`` times the squared RMS of one fitted to the rim's, 0 when the
        rim's left under ``lead`` times theirs, at the last comparison that told them apart
        (:meth:`observe_path`); before one has, as the calibration day chose (``prior``)."""
        if self._always:
            return 1.0
        return self._prior if self._path_choice is None else self._path_choice

    def observe_path(self, t: float, rim_enu: np.ndarray, rings_enu: np.ndarray) -> None:
        """Count one frame's two fixes (ENU) as sights of the sun at POSIX ``t``, without the
        site.  The sun's diurnal path is fixed by the site alone; an error of a locator that
        grows and shrinks with the sun's elevation (a sky model's) bends its sights off any
        such path, which no site fitted to them takes up.  So each locator's sights get their
        own site (:func:`.selfsite.fit_site`), and the residuals are compared as the squared
        angles to the ephemeris are with the site (third renderer, 20-min frames: the rim's
        site fitted to 0.09-0.11 deg, the rings' to 0.016-0.032, their errors 0.10-0.14 and
        0.014-0.032; the second renderer's look as described 0.010-0.021 and 0.065-0.075).

        Where the sun keeps to a few degrees of elevation all day (20 Mar at 70 N: 12-20 deg),
        a sky model's error that grows towards noon has the shape of a change of latitude and
        a site takes it up: the third renderer's rim, 0.2 deg off at noon, fits its own site
        to 0.037-0.047 deg, the rings to 0.028-0.033.  A comparison that leaves neither under
        its lead (:func:`path_lead`, ``lead`` at most) times the other tells nothing: it
        neither chooses nor undoes an earlier choice, and a camera that has never chosen stays
        halfway (0.0942 -> 0.0553 deg RMS there at 640 x 480, 0.0883 -> 0.0534 at 1280 x 960;
        docs/fisheye-rounds.md, a thirty-eighth round)."""
        from .selfsite import MIN_SHARE, fit_site

        if self._path and t - self._path[-1][0] < PATH_STEP_S:
            return
        if float(rim_enu[2]) < math.sin(math.radians(PATH_MIN_EL_DEG)):
            return  # under it the rim is cut by the horizon, its errors erratic (CIE sky 10)
        self._path.append((t, rim_enu, rings_enu))
        while t - self._path[0][0] > PATH_KEEP_S:
            self._path.popleft()
        self._path_new += 1
        ts = np.array([p[0] for p in self._path])
        if len(ts) < PATH_MIN_SIGHTS or ts[-1] - ts[0] < PATH_MIN_SPAN_S:
            return
        if min(float(p[1][2]) for p in self._path) > math.sin(math.radians(PATH_LOW_EL_DEG)):
            return
        if self._path_choice is not None and self._path_new < PATH_EVERY:
            return
        self._path_new = 0
        sq, used = [], len(ts)
        for k in (1, 2):
            fit = fit_site(ts, np.array([p[k] for p in self._path]))
            ok = fit is not None and fit[0].n >= MIN_SHARE * len(ts)
            sq.append(fit[0].rms_deg ** 2 if ok and fit is not None else math.inf)
            used = min(used, fit[0].n) if ok and fit is not None else used
        if math.isfinite(min(sq)):
            self._path_sq = (sq[0], sq[1])
            lead = min(self._lead, path_lead(used, PATH_SIGNIFICANCE))
            if sq[1] < lead * sq[0]:
                self._path_choice = 1.0
            elif sq[0] < lead * sq[1]:
                self._path_choice = 0.0

    def _learned(self, with_site: bool) -> bool:
        """Whether frames have set :meth:`weight` (with the site) or :meth:`path_weight`."""
        return len(self._err) >= max(self._min, 1) if with_site else self._path_choice is not None

    @property
    def rim_settled(self) -> bool:
        """The rings have weighed nothing over ``settled`` frames at least: they are then read
        only on frames whose elevation gives them a weight, and on one frame in ``every``
        (they cost 0.3 ms a frame)."""
        if self._always or len(self._err) < max(self._settled, 1):
            return False
        return self.weight() == 0.0

    def observe(self, el_deg: float, rim: np.ndarray, rings: np.ndarray, sun: np.ndarray) -> None:
        """Count one frame's two fixes ``rim``, ``rings`` (ENU) against the ``sun``'s direction
        at elevation ``el_deg`` (deg), where both lie within ``max_deg`` of it."""
        lim = math.cos(math.radians(self._max))
        if float(rim @ sun) >= lim and float(rings @ sun) >= lim:
            self._err.append((el_deg, rim - sun, rings - sun))
            self._all_w = self._airmass = None

    def place(
        self,
        cand: Any,
        gates: list[Any],
        R: np.ndarray | None,
        up_cam: np.ndarray | None,
        lens: Any,
        t: float | None = None,
    ) -> Any:
        """``cand`` (a :class:`.default.Candidate`), placed at the camera's weight between its
        rim's fix and its rings' (:meth:`weight`) when that passes every gate of ``gates``
        (:class:`.gates.Gate`; the ephemeris's among them); the frame counts towards the weight
        either way.  Where the rings weigh but place no sun (a cloud in them) or not within the
        gates, the rim's fix moved by that weight of its offset from the rings'
        (:meth:`rim_as_rings`).  Without the ephemeris's gate (no site) the weight is 0 or 1,
        as the sun's path chooses (:meth:`path_weight`; the prior until it has), and the frame at POSIX ``t`` counts as
        sights of that path (:meth:`observe_path`).  ``R``: ENU from camera; ``lens``
        (:class:`.lens.FisheyeLens`) puts the fix's centre in the image."""
        reading = cand.fit.sky_reading
        gate = next((g for g in gates if g.name == "ephemeris"), None)
        if cand.d_enu is None or R is None or up_cam is None or (gate is None and t is None):
            return cand
        # weighed from the frames before: never from this frame's fixes
        d, w = None, self.weight(float(cand.el_deg)) if gate is not None else self.path_weight()
        if reading is not None:
            self._frames += 1
            if w == 0.0 and self.rim_settled and self._frames % self._every:
                return cand
            d = ring_direction(reading, up_cam, by_airmass=gate is not None)
        if d is not None:
            d_enu = R @ d
            if self._unknown and not self._learned(gate is not None):
                apart = math.degrees(math.acos(min(1.0, float(cand.d_cam @ d))))
                w = min(w, UNKNOWN_MAX_MOVE_DEG / max(apart, 1e-9))
            if gate is not None:
                self.observe(float(cand.el_deg), cand.d_enu, d_enu, gate.centre)
            elif t is not None:
                self.observe_path(float(t), cand.d_enu, d_enu)
            v, h = _vertical_basis(d, up_cam)
            el = math.degrees(math.asin(min(max(float(d_enu[2]), -1.0), 1.0)))
            offset = (float((cand.d_cam - d) @ v), float((cand.d_cam - d) @ h))
            learned = self.median_offset(el)
            self._offsets.append((el, *offset))
            astray = learned is not None and math.degrees(math.dist(offset, learned)) > OFFSET_ASTRAY_DEG
            fix = _between(cand.d_cam, d, w)
            if w > 0.0 and not astray and self._within(fix, R, gates):
                return self._placed(cand, fix, R, lens, "ring_locator")
        if w > 0.0:
            moved = self.rim_as_rings(cand.d_cam, float(cand.el_deg), up_cam)
            if moved is not None:
                fix = _between(cand.d_cam, moved, w)
                if self._within(fix, R, gates):
                    return self._placed(cand, fix, R, lens, "rim_by_rings")
        return cand

    def median_offset(self, el_deg: float) -> tuple[float, float] | None:
        """The rim's median offset from the rings' fix (rad, along the vertical and across) on
        the frames before where both placed the sun within :data:`OFFSET_EL_DEG` of
        ``el_deg`` (deg), else on the :data:`MIN_OFFSETS` nearest in elevation within
        :data:`NEAREST_OFFSET_DEG`; None with fewer."""
        near = [(dv, dh) for el, dv, dh in self._offsets if abs(el - el_deg) <= OFFSET_EL_DEG]
        if len(near) < MIN_OFFSETS:
            nearest = sorted(self._offsets, key=lambda o: abs(o[0] - el_deg))[:MIN_OFFSETS]
            near = [(dv, dh) for el, dv, dh in nearest if abs(el - el_deg) <= NEAREST_OFFSET_DEG]
        if len(near) < MIN_OFFSETS:
            return None
        dv, dh = np.median(np.array(near), axis=0)
        return float(dv), float(dh)

    def rim_as_rings(self, rim: np.ndarray, el_deg: float, up_cam: np.ndarray) -> np.ndarray | None:
        """The rim's fix ``rim`` (camera frame) less its learned offset from the rings' fixes
        at ``el_deg`` (:meth:`median_offset`), or None before one is learned (the caller
        moves the rim by its weight of that).  Where the rings read the sun better, the rim's
        error is mostly its sky model's, which keeps its size and sign at an elevation and
        changes slowly with it: the third renderer's clouds with the site, 0.240 -> 0.21 deg
        RMS, where 187 suns the rings did not place read 0.316 by the rim; the second
        renderer's power-law aureole at 5 deg, whose rings placed no sun below 7 (0.174 ->
        0.016 deg).  So a frame whose own rings put its rim farther than
        :data:`OFFSET_ASTRAY_DEG` from that offset has rings astray, and is placed this way too
        (:meth:`place`)."""
        learned = self.median_offset(el_deg)
        if learned is None:
            return None
        dv, dh = learned
        v, h = _vertical_basis(rim, up_cam)
        d = rim - dv * v - dh * h
        return d / np.linalg.norm(d)

    @staticmethod
    def _within(d: np.ndarray, R: np.ndarray, gates: list[Any]) -> bool:
        d_enu = R @ d
        return all(g.distance_deg(d_enu if g.frame == "enu" else d) <= g.radius_deg for g in gates)

    @staticmethod
    def _placed(cand: Any, d: np.ndarray, R: np.ndarray, lens: Any, flag: str) -> Any:
        """``cand`` placed at ``d`` (camera frame), flagged ``flag``; ``cand`` itself when ``d``
        is not in front of the lens."""
        uv, seen = lens.project(d[None, :])
        if not seen[0]:
            return cand
        d_enu = R @ d
        el = math.degrees(math.asin(min(max(float(d_enu[2]), -1.0), 1.0)))
        fit = replace(cand.fit, flags=[*cand.fit.flags, flag], centre_uv=(float(uv[0, 0]), float(uv[0, 1])))
        return replace(cand, fit=fit, d_cam=d, d_enu=d_enu, el_deg=el)


def _between(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """The unit direction ``w`` of the way from ``a`` to ``b`` (both unit vectors)."""
    d = a + w * (b - a)
    return d / np.linalg.norm(d)


def _vertical_basis(d: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents at ``d``: towards the zenith ``up`` and across (both camera frame)."""
    v = up - float(up @ d) * d
    v = v / max(float(np.linalg.norm(v)), 1e-12)
    return v, np.cross(d, v)
