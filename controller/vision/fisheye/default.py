"""The default fisheye pipeline: calibrated directions from the glare's rim, judged in angle.

Per frame (docs/fisheye.md has the reasoning and the measured figures):

1. on the mean of each pixel's two darkest channels (:func:`.channel.glare_channel`), grey
   levels within ``sat_margin`` of the frame's peak form blobs; each blob's inscribed-disk centres
   are candidates (:mod:`.glare`);
2. each candidate's rim is measured to a fraction of a pixel and fitted, through the
   calibrated lens, by a small circle on the sphere (:func:`.glare.fit_glare`);
3. **visibility**: a candidate is the sun only if its glare is round on the sphere (rim RMS),
   complete (inliers all round it), of a plausible angular size, stands out from the sky,
   has a full core, and (orientation known) is above the horizon; an occluded or
   cloud-mangled sun therefore yields no observation, with the reason;
4. **gates** (:mod:`.gates`): the previous accepted detection of the sequence (the paper's
   rule 3, in angle), a caller's prior (the loop's sun-path filter), the ephemeris (bundle
   ``[site]``); among several sun-like candidates with no gate to tell them apart, the
   clearly largest glare is the sun, otherwise the frame is ``ambiguous_candidates``.

The output is a :class:`~.result.FisheyeResult` with a one-sigma uncertainty and quality
flags; ``observation()`` gives the :class:`~controller.sun.types.SunObservation`.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ...calibration.fisheye_bundle import FisheyeBundle
from ...sun.source import Site
from ...sun.types import enu_to_azel
from .blend import LearnedBlend
from .blobs import find_blobs
from .channel import FrameBuffers, glare_channel
from .frames import load_mask, sited, with_sky_scale
from .gates import Ephemeris, Gate, GateOptions, min_rim_share, prior_direction, track_prediction
from .glare import GlareFit, GlareOptions
from .history import GlareHistory
from .lens import FisheyeLens
from .locator import LocatorChoice
from .pipeline import FramePipeline
from .radiometry import Radiometry
from .result import FisheyeResult, not_found
from .selfsite import LearnedEphemeris, SiteFit, SiteFromSun
from .smear import column_smear, fit_smeared

#: Order in which a refused frame's reason is reported when candidates failed differently.
REASON_ORDER = tuple(
    "lens_ghost static_glare glare_shrunk below_horizon irregular_glare incomplete_glare"
    " sky_dominated low_contrast glare_too_small glare_too_large no_rim".split()
)


@dataclass(frozen=True)
class FisheyeOptions:
    """Decision thresholds of the default pipeline (angles in degrees).

    All are physical or geometric (angular sizes, fractions of the rim), none in pixels of
    one particular camera except ``max_rms_px``, the rim's roughness relative to the pixel (a
    cloud-mangled sun's rim is rough by a few per cent of its radius, a saturated cloud patch
    by tens of per cent; our broken-cloud suite's visible suns: median 0.07 px and 0.6 %, p95
    0.20 px and 1.8 %; a thin cloud's bright halo around a dimmed sun, fitted 1-5 deg off it,
    4 % in the median: the third renderer's clouds without the site gave 45 such detections
    with 0.6 px + 8 %, 25 with 0.3 px + 4 %; 0.3 px + 3 % cost our suite a miss and, without
    the site, a false detection; docs/fisheye.md step 8), and ``small_glare_px``: a glare a few
    pixels in radius must show ``small_min_inlier_fraction`` of its rim (a rim of a few pixels
    on part of its rays is a sunlit cloud's fleck: 35-71 % of their rays on both renderers'
    broken-cloud suites; suns dimmed by thin cloud 83-100 % and 56-92 %).
    A rim whose largest gap is the sky's (most of its rays found no rim, and it faces the
    horizon, its middle within 60 deg of down the vertical through the glare, or near the
    horizon the zenith: the clear sky brightens towards the horizon until the rays clip, or
    the sky's model is a guess) may miss ``max_horizon_gap_deg`` at most: the arc left
    carries that model's error on its radius straight into its centre (second renderer,
    wide glare, 15-19 deg: 0.15-0.70 deg off with 100-113 deg gaps; 83-97 deg gaps within
    0.05).  A cloud's gap is of rays whose rims it pulled in (outliers): ``max_gap_deg``.
    A glare whose centre the sky's correction of its rim moved more than ``max_sky_move_deg``
    (its first harmonic on the rays, as measured; sigma takes the fitted move, :mod:`.sphere`)
    is refused (``sky_dominated``): that centre is the sky model's, good to 5-15 % (a 1-deg
    move: 0.05-0.15 deg). On 12 clear looks of both renderers the 9 frames that moved 1.1-1.6
    deg read 0.08-0.21 deg off (a hard-edged disk in a bright sky at 18-19 deg, both sizes; CIE
    sky 15 clipping about a sun at 27 deg); the 26 that moved 0.6-0.96 deg, within 0.11.
    A sun whose own sigma exceeds ``max_sigma_deg`` is refused (``imprecise_glare``): no gate or
    loop can use it, and a wrong one that size is what it stands for (a rim held on 35 % of its
    rays at 14.5 deg, sigma 1.8, 0.89 off; our bright sky at 22-24 deg, sigma 1.2-1.3, 0.10-0.14
    off).  Under ``near_horizon_deg`` the bound is ``max_sigma_near_horizon_deg``: there the
    error is the elevation model's, the same way frame after frame (CIE sky type 10 at 5-10
    deg: sigma 0.53-0.90, all read 0.09-0.42 high), which a filter takes for noise.
    """

    glare: GlareOptions = field(default_factory=GlareOptions)
    gates: GateOptions = field(default_factory=GateOptions)
    min_peak: float = 200.0  # grey level: below it nothing is saturated
    sat_margin: float = 4.0  # grey levels under the peak that count as saturated
    min_radius_deg: float = 0.8  # the sun's disk is 0.27 deg; smaller: a point source, or too dim
    max_radius_deg: float = 20.0
    min_inlier_fraction: float = 0.35
    small_glare_px: float = 4.0  # a glare this small (radius) must show nearly all its rim
    small_min_inlier_fraction: float = 0.8
    max_gap_deg: float = 150.0  # largest arc of the rim without an inlier
    max_horizon_gap_deg: float = 100.0  # ... when that arc faces the horizon
    max_rms_px: float = 0.3  # rim residual RMS: this many pixels at the glare ...
    max_rms_rel: float = 0.04  # ... plus this fraction of its radius
    min_core_fill: float = 0.9
    max_last_move_deg: float = 0.1  # a fit still moving this much at its last pass: unsettled
    max_sigma_deg: float = 1.0  # a sun placed no better than this is no observation
    max_sigma_near_horizon_deg: float = 0.5  # the same under near_horizon_deg (see above)
    max_sky_move_deg: float = 1.0  # the sky's correction moved the centre further: the sky's, not the glare's
    min_contrast: float = 0.12  # (peak - sky) / peak
    horizon_margin_deg: float = 1.0
    ambiguity_ratio: float = 1.25  # the sun's glare must be this much larger
    ghost_align_deg: float = 2.0  # a smaller glare this close to opposite a larger one: its ghost
    max_blobs: int = 6
    sigma_floor_deg: float = 0.015
    sky_sigma_share: float = 0.5  # the sky's correction of the rim is trusted to half its size
    near_horizon_deg: float = 12.0


@dataclass
class Candidate:
    fit: GlareFit
    d_cam: np.ndarray
    d_enu: np.ndarray | None
    el_deg: float | None
    reason: str | None


class FisheyeEstimator(FramePipeline):
    """The default pipeline for one camera (one bundle); it remembers the last accepted
    detection of the current sequence (call :meth:`reset_sequence` between sequences)."""

    algorithm = "default"

    def __init__(self, bundle: FisheyeBundle, options: FisheyeOptions | None = None):
        self.bundle = bundle
        self.options = with_sky_scale(options or FisheyeOptions(), bundle.orientation, bundle.site)
        cam = bundle.camera
        self.lens = FisheyeLens.from_camera(cam)
        self.shape = (cam.height, cam.width)
        self.buffers = FrameBuffers()  # frame-sized work arrays, reused frame after frame
        self.R = bundle.enu_from_camera
        self.up_cam = None if self.R is None else self.R[2].copy()
        self.radiometry = Radiometry.from_cal(bundle.radiometry)
        self.frame = "enu" if self.R is not None else "model"
        self.mask = load_mask(bundle, self.shape)
        self.ephemeris = None
        if bundle.site is not None and self.R is not None and self.options.gates.ephemeris:
            s = bundle.site
            self.ephemeris = Ephemeris(Site(latitude=s.latitude, longitude=s.longitude, altitude=s.altitude))
        g = self.options.gates
        learn = self.R is not None and self.ephemeris is None and g.learn_site  # no site: from the sun's
        self.site_from_sun = SiteFromSun() if learn else None  # own sights (:mod:`.selfsite`)
        self._sited = sited(self.options.glare) if learn and g.sited_once_learned else None
        self.learned: tuple[SiteFit, LearnedEphemeris] | None = None
        self.locator = LocatorChoice.of_camera(g, bundle.orientation)  # used with the site
        # the rims' blend of metrics, learned (the camera's: kept); with the site only, see .blend
        self.blend = LearnedBlend() if self.ephemeris is not None else None
        self._last: tuple[float, np.ndarray] | None = None
        self._refused_by_anchor = 0  # frames since the anchor in which it alone refused the sun
        self._anchors: deque[tuple[float, np.ndarray]] = deque(maxlen=16)  # the track's
        self.history = GlareHistory()
        lens_sig = 0.5 * (cam.rms_px or 0.0) * self.lens.deg_per_px(cam.cx, cam.cy)
        o = bundle.orientation
        ori_sig = 0.0 if o is None or o.residual_deg is None else o.residual_deg / math.sqrt(o.frames or 1)
        self.sigma_cal = math.hypot(lens_sig, ori_sig)

    # -- sequence --------------------------------------------------------------------------
    def reset_sequence(self) -> None:
        """Forget the last accepted detection and the glares seen (a new sequence starts)."""
        self._last = None
        self._refused_by_anchor = 0
        self._anchors.clear()
        self.history.clear()
        # the site learned from the sun stays: it is the camera's, not the sequence's

    # -- entry points ------------------------------------------------------------------------
    def estimate_image(self, image, t: float | None = None, prior=None) -> FisheyeResult:
        """Measure the sun in one frame (BGR or grey, 8 or 16 bit) taken at POSIX time ``t``.

        ``prior``: an expected sun direction (``az_deg``, ``el_deg``, ``sigma_deg`` in ENU,
        e.g. the sun-path filter's prediction) that the detection must agree with.
        """
        o = self.options
        img, refused = self.checked_frame(image, t)
        if img is None:
            assert refused is not None
            return refused
        grey = glare_channel(img, self.buffers)
        _, peak, _, _ = cv2.minMaxLoc(grey, self.mask)
        if peak < o.min_peak:
            return not_found(None, "no_sun_glare", t, self.frame, self.algorithm, peak=int(peak))
        blobs = find_blobs(
            grey,
            peak - o.sat_margin,
            self.mask,
            max_blobs=o.max_blobs,
            mask_out=self.buffers.get("binary", grey.shape),
        )
        if sum(b.area_px for b in blobs) > 0.5 * grey.size:
            return not_found(None, "overexposed", t, self.frame, self.algorithm)
        if self.learned is not None and self.site_from_sun is not None and self.site_from_sun.stale(t):
            self.site_from_sun, self.learned = SiteFromSun(), None  # anew; measured as without
        glare = self._sited if self._sited is not None and self.learned is not None else o.glare
        self._smear = column_smear(grey, blobs, float(peak)) if glare.column_smear else None
        cands: list[Candidate] = []
        low = 0
        for blob in blobs:
            for x, y, r in blob.centres:
                if any(
                    math.hypot(x - c.fit.centre_uv[0], y - c.fit.centre_uv[1]) < c.fit.radius_px
                    for c in cands
                ):
                    continue  # another centre of a glare already measured
                if self._below_horizon(x, y, r):
                    low += 1
                    continue
                cand = self._measure(grey, x, y, r, float(peak), glare)
                if cand is not None and cand.reason is not None and cand.fit.one_way_streak:
                    # a saturated cloud below (or above) a dimmed sun may pass for a streak
                    # that leaves one way; if the rim it leaves is not the sun's, drop it
                    cand = (
                        self._measure(grey, x, y, r, float(peak), replace(glare, one_way_streaks=False))
                        or cand
                    )
                if cand is not None:
                    cands.append(cand)
        sun_like = [c for c in cands if c.reason is None]
        if t is not None and sun_like:
            sun_like = self._motion_vetoes(t, sun_like, prior)
        if not sun_like:
            reasons = Counter(c.reason for c in cands)
            if not cands:  # blobs below the horizon explain the frame only when alone
                reasons["below_horizon"] += low
            why = next((r for r in REASON_ORDER if reasons.get(r)), "no_rim")
            extra: dict[str, float | int] = {"candidates": len(cands) + low}
            if cands:  # how wide the widest refused glare was: tens of degrees is the sky's
                extra["glare_radius_deg"] = round(max(c.fit.radius_deg for c in cands), 2)  # patch
            return not_found(None, why, t, self.frame, self.algorithm, **extra)
        gates = self._gates(t, prior)
        passing = [
            c for c in sun_like if all(g.distance_deg(self._in(c, g.frame)) <= g.radius_deg for g in gates)
        ]
        if gates and not passing:
            self._release_a_stale_anchor(t, sun_like, gates)
            if self.site_from_sun is not None:  # the learned site's gate's refusals
                self.site_from_sun.gate_refused(t, gates, [c.d_enu for c in sun_like])
            near = min(
                max(g.distance_deg(self._in(c, g.frame)) - g.radius_deg for g in gates) for c in sun_like
            )
            beyond: dict[str, object] = {"gates": [g.name for g in gates], "beyond_gate_deg": round(near, 3)}
            return not_found(None, "gate_rejected", t, self.frame, self.algorithm, **beyond)
        passing.sort(key=lambda c: -c.fit.radius_deg)
        flags = ["several_candidates"] if len(sun_like) > 1 else []
        best = passing[0]
        if len(passing) > 1 and passing[1].fit.radius_deg * o.ambiguity_ratio > best.fit.radius_deg:
            close = [c for c in passing if c.fit.radius_deg * o.ambiguity_ratio > best.fit.radius_deg]
            movers = [c for c in close if t is not None and self.history.moves_like_the_sun(t, self._gd(c))]
            if gates:
                g = gates[0]
                best = min(passing, key=lambda c: g.distance_deg(self._in(c, g.frame)))
            elif len(movers) == 1:
                best = movers[0]
                flags.append("chosen_by_motion")
            else:
                return not_found(
                    None, "ambiguous_candidates", t, self.frame, self.algorithm, candidates=len(passing)
                )
        if self.locator is not None and t is not None:  # a camera whose sky is a product (.rings)
            best = self.locator.place(best, gates, self.R, self.up_cam, self.lens, float(t))
        res = self._result(best, t, flags + [f"gate_{g.name}" for g in gates])
        bound = o.max_sigma_near_horizon_deg if "near_horizon" in res.quality else o.max_sigma_deg
        if res.sigma_deg is not None and res.sigma_deg > bound:
            return not_found(
                None, "imprecise_glare", t, self.frame, self.algorithm, sigma_deg=round(res.sigma_deg, 3)
            )
        share = best.fit.inlier_fraction
        if share < min_rim_share(o.gates, gates):  # a weak rim that nothing else vouches for
            return not_found(
                None, "unvouched_glare", t, self.frame, self.algorithm, rim_share=round(share, 3)
            )
        if t is not None:
            if share >= o.gates.anchor_min_inlier_fraction:
                self._last = (float(t), self._gd(best))
                self._refused_by_anchor = 0
                self._anchors.append(self._last)
                self._learn_site(float(t), best)
                if self.blend is not None:
                    self.blend.observe(best.fit.axis, best.fit.image_share, best.fit.image_share_sigma, t)
            self.history.accepted(float(t), best.fit.radius_deg)
        return res

    # -- internals ---------------------------------------------------------------------------
    def _measure(
        self, grey: np.ndarray, x: float, y: float, r: float, peak: float, opts: GlareOptions
    ) -> Candidate | None:
        """The glare around (``x``, ``y``) fitted and judged, or None when no rim was found;
        the rim's blend of metrics has the camera's prior in that direction (:mod:`.blend`)."""
        if self.blend is not None:
            d, ok = self.lens.rays([[x, y]])
            opts = replace(opts, blend_prior=self.blend.prior(d[0])) if ok[0] else opts
        fit = fit_smeared(grey, self.lens, (x, y, r), peak, opts, self._smear, self.up_cam, self.radiometry)
        return None if fit is None else self._judge(fit)

    def _judge(self, fit: GlareFit) -> Candidate:
        o = self.options
        d_cam = fit.axis
        d_enu = self.R @ d_cam if self.R is not None else None
        el = float(math.degrees(math.asin(np.clip(d_enu[2], -1, 1)))) if d_enu is not None else None
        reason = None
        if (
            fit.rms_deg > o.max_rms_px * fit.deg_per_px + o.max_rms_rel * fit.radius_deg
            or fit.core_fill < o.min_core_fill
            or fit.last_move_deg > o.max_last_move_deg
        ):
            reason = "irregular_glare"
        elif (
            fit.inlier_fraction < o.min_inlier_fraction
            or fit.max_gap_deg > o.max_gap_deg
            or (fit.sky_gap and fit.max_gap_deg > o.max_horizon_gap_deg)
            or (fit.radius_px < o.small_glare_px and fit.inlier_fraction < o.small_min_inlier_fraction)
        ):
            reason = "incomplete_glare"
        elif fit.sky_harmonic_deg > o.max_sky_move_deg:
            reason = "sky_dominated"
        elif fit.contrast < o.min_contrast:
            reason = "low_contrast"
        elif fit.radius_deg < o.min_radius_deg:
            reason = "glare_too_small"
        elif fit.radius_deg > o.max_radius_deg:
            reason = "glare_too_large"
        elif el is not None and el < -o.horizon_margin_deg:
            reason = "below_horizon"
        return Candidate(fit, d_cam, d_enu, el, reason)

    def _release_a_stale_anchor(self, t: float | None, sun_like: list[Candidate], gates: list[Gate]) -> None:
        """Drop the sequence gate's anchor once it alone has refused, in ``release_after``
        frames, a sun-like glare that moves like the sun (:meth:`.GlareHistory.moves_like_the_sun`):
        the anchor was then a detection off the sun (a cloud's bright edge it drifted onto by
        steps within the gate), and keeping it would shut the sun out until it expires."""
        if t is None or not any(g.name == "sequence" for g in gates):
            return
        others = [g for g in gates if g.name != "sequence"]
        if any(
            all(g.distance_deg(self._in(c, g.frame)) <= g.radius_deg for g in others)
            and self.history.moves_like_the_sun(float(t), self._gd(c))
            for c in sun_like
        ):
            self._refused_by_anchor += 1
            if self._refused_by_anchor >= self.options.gates.release_after:
                self._last, self._refused_by_anchor = None, 0
                self._anchors.clear()

    def _learn_site(self, t: float, c: Candidate) -> None:
        """Take an anchoring detection as a sight of the sun; gate by the site they agree on."""
        if self.site_from_sun is None or c.d_enu is None:
            return
        fit = self.site_from_sun.add(t, c.d_enu)
        if fit is None:
            self.learned = None
        elif self.learned is None or self.learned[0] != fit:
            self.learned = (fit, LearnedEphemeris(fit))

    def _gd(self, c: Candidate) -> np.ndarray:
        """The candidate's direction in the frame the sequence is judged in."""
        return c.d_enu if c.d_enu is not None else c.d_cam

    def _motion_vetoes(self, t: float, sun_like: list[Candidate], prior) -> list[Candidate]:
        """Record the sun-like glares; without the ephemeris or a prior to go by, drop those
        that stand still or are much smaller than the sun recently seen (:mod:`.history`)."""
        self.history.add(float(t), [(self._gd(c), c.fit.radius_deg) for c in sun_like])
        if self.ephemeris is not None or prior is not None:
            return sun_like
        kept = []
        for c in sun_like:
            if self._is_ghost(c, sun_like):
                c.reason = "lens_ghost"
            elif self.history.is_static(float(t), self._gd(c)):
                c.reason = "static_glare"
            elif self.history.is_shrunk(float(t), c.fit.radius_deg):
                c.reason = "glare_shrunk"
            else:
                kept.append(c)
        return kept

    def _is_ghost(self, c: Candidate, others: list[Candidate]) -> bool:
        """A lens flare ghost lies on the line from the sun's image through the principal
        point, on the other side, and is fainter: smaller than the glare it mirrors."""
        cx, cy = self.lens.cx, self.lens.cy
        opposite = -math.cos(math.radians(self.options.ghost_align_deg))
        gx, gy = c.fit.centre_uv[0] - cx, c.fit.centre_uv[1] - cy
        for o in others:
            if o is c or o.fit.radius_deg <= c.fit.radius_deg:
                continue
            sx, sy = o.fit.centre_uv[0] - cx, o.fit.centre_uv[1] - cy
            norm = math.hypot(gx, gy) * math.hypot(sx, sy)
            if norm > 0 and (gx * sx + gy * sy) / norm < opposite:
                return True
        return False

    def _below_horizon(self, x: float, y: float, r_px: float) -> bool:
        """The whole blob lies below the horizon (orientation known): not worth a fit."""
        if self.R is None:
            return False
        d, ok = self.lens.rays([[x, y]])
        if not ok[0]:
            return False
        el = math.degrees(math.asin(float(np.clip((self.R @ d[0])[2], -1, 1))))
        return el + r_px * self.lens.deg_per_px(x, y) < -self.options.horizon_margin_deg

    def _in(self, c: Candidate, frame: str) -> np.ndarray:
        return c.d_enu if frame == "enu" and c.d_enu is not None else c.d_cam

    def _gates(self, t: float | None, prior) -> list[Gate]:
        g = self.options.gates
        out: list[Gate] = []
        pd = prior_direction(prior) if self.R is not None else None
        if pd is not None:
            out.append(
                Gate("prior", pd[0], max(g.prior_min_deg, g.prior_k_sigma * pd[1] + g.base_deg), "enu")
            )
        if self.ephemeris is not None and t is not None:
            o = self.bundle.orientation
            slack = 0.0  # narrowed by the rotation's own error, as the learned site's (.gates)
            if o is not None and o.residual_deg is not None:
                slack = 2.0 * o.residual_deg / math.sqrt(max(o.frames or 1, 1))
            out.append(Gate("ephemeris", self.ephemeris.direction(t), g.ephemeris_deg - slack, "enu"))
        if self.learned is not None and t is not None:
            fit, eph = self.learned  # narrowed by the learned sun's own error (see .gates)
            slack = 2.0 * fit.rms_deg / math.sqrt(fit.n)
            out.append(Gate("ephemeris_learned", eph.direction(t), g.ephemeris_deg - slack, "enu"))
        if self._last is not None and t is not None:
            dt = float(t) - self._last[0]
            if 0.0 <= dt <= g.max_gap_s:
                centre, radius = self._last[1], g.base_deg + g.rate_deg_per_min * dt / 60.0
                if not out:  # no site, no prior: the sun's own track, where known, is tighter
                    recent = [a for a in self._anchors if float(t) - a[0] <= g.max_gap_s]
                    pred = track_prediction(recent, float(t), g.track_min_s)
                    if pred is not None:
                        centre = pred[0]
                        track = g.track_rate_deg_per_min * dt / 60.0 + g.track_anchor_deg * dt / pred[1]
                        radius = min(radius, g.base_deg + track)
                out.append(Gate("sequence", centre, radius, self.frame if self.R is not None else "camera"))
        return out

    def _result(self, c: Candidate, t: float | None, flags: list[str]) -> FisheyeResult:
        o = self.options
        f = c.fit
        v = c.d_enu if c.d_enu is not None else c.d_cam
        az, el = enu_to_azel(v)
        sig_fit = f.rms_deg * math.sqrt(2.0 / max(f.n_inliers, 3))
        # a rim bent by a cloud nearby, or partly lost to one, moves the centre by a share of
        # the bending and of the radius: systematic, not averaged down by the rays
        sig_rim = 0.5 * f.rms_deg
        sig_partial = 0.5 * f.radius_deg * (1.0 - f.inlier_fraction) ** 2
        # a fit still moving at its last pass has not settled: its step is part of the error;
        # so is a share of how far the sky's correction moved the centre (a sky that
        # brightens steeply around a low sun is modelled only in part)
        sigma = math.sqrt(
            sig_fit**2
            + sig_rim**2
            + o.sigma_floor_deg**2
            + self.sigma_cal**2
            + sig_partial**2
            + f.last_move_deg**2
            + (o.sky_sigma_share * f.sky_move_deg) ** 2
        )
        if f.inlier_fraction < 0.9:
            flags.append("outliers_rejected")
        if f.smear:
            flags.append(f.smear)
        flags += f.flags
        if c.el_deg is not None and c.el_deg < o.near_horizon_deg:
            flags.append("near_horizon")
            sigma += 0.01 * (o.near_horizon_deg - c.el_deg)
        x, y, z = (float(a) for a in c.d_cam)
        W, H = self.shape[1], self.shape[0]
        return FisheyeResult(
            image=None,
            found=True,
            time=t,
            frame=self.frame,
            algorithm=self.algorithm,
            az_deg=float(az),
            el_deg=float(el),
            sigma_deg=sigma,
            d_cam=c.d_cam,
            centre_uv=f.centre_uv,
            offset_px=(f.centre_uv[0] - W / 2, f.centre_uv[1] - H / 2),
            offset_deg=(math.degrees(math.atan2(x, z)), math.degrees(math.atan2(y, z))),
            radius_deg=f.radius_deg,
            quality=tuple(flags),
            extra={
                "rim_rms_deg": round(f.rms_deg, 5),
                "rim_inliers": f.n_inliers,
                "rim_rays": f.n_rays,
                "last_move_deg": round(f.last_move_deg, 5),
            },
        )
