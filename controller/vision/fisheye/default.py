"""The default fisheye pipeline: calibrated directions from the glare's rim, judged in angle.

Per frame (docs/fisheye.md has the reasoning and the measured figures):

1. on the mean of each pixel's two darkest channels (:func:`.channel.glare_channel`), grey
   levels within ``sat_margin`` of the frame's peak form blobs; each blob's inscribed-disk centres
   are candidates (:mod:`.glare`);
2. each candidate's rim is measured to a fraction of a pixel and fitted, through the
   calibrated lens, by a small circle on the sphere (:func:`.glare.fit_glare`);
3. **visibility** (:mod:`.visibility`): a candidate is the sun only if its glare is round
   on the sphere (rim RMS), complete (inliers all round it), of a plausible angular size,
   stands out from the sky, has a full core, and (orientation known) is above the horizon;
   an occluded or cloud-mangled sun therefore yields no observation, with the reason;
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
from dataclasses import replace

import cv2
import numpy as np

from ...calibration.fisheye_bundle import FisheyeBundle
from ...sun.source import Site
from ...sun.types import enu_to_azel
from .blend import LearnedBlend
from .blobs import Blob, find_blobs
from .channel import FrameBuffers, glare_channel
from .frames import load_mask, sited, with_sky_scale
from .gates import (
    CameraPrior,
    Ephemeris,
    Gate,
    max_self_vouched_sigma,
    min_rim_share,
    prior_direction,
    track_prediction,
)
from .glare import GlareFit, GlareOptions
from .history import GlareHistory
from .lens import FisheyeLens
from .locator import LocatorChoice
from .pipeline import FramePipeline
from .radiometry import Radiometry
from .result import FisheyeResult, not_found
from .selfsite import LearnedEphemeris, SiteFit, SiteFromSun
from .smear import column_smear, fit_smeared
from .visibility import REASON_ORDER, Candidate, FisheyeOptions, glare_sigma, judge


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
        e.g. the sun-path filter's prediction), or a :class:`~.gates.CameraPrior` in the
        camera's frame, that the detection must agree with.
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
        cands, low = self._candidates(grey, blobs, float(peak), glare)
        sun_like = [c for c in cands if c.reason is None]
        if t is not None and sun_like:
            sun_like = self._motion_vetoes(t, sun_like, prior)
        if not sun_like:
            return self._no_sun(cands, low, t)
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
            off = self._off_the_sun(sun_like, gates)
            if off is not None:  # one offset frame after frame: the camera moved (.mount_watch)
                beyond["glare_offset_deg"] = off
            return not_found(None, "gate_rejected", t, self.frame, self.algorithm, **beyond)
        flags = ["several_candidates"] if len(sun_like) > 1 else []
        best = self._choose(passing, gates, t, flags)
        if best is None:
            return not_found(
                None, "ambiguous_candidates", t, self.frame, self.algorithm, candidates=len(passing)
            )
        if self.locator is not None and t is not None:  # a camera whose sky is a product (.rings)
            best = self.locator.place(best, gates, self.R, self.up_cam, self.lens, float(t))
        res = self._result(best, t, flags + [f"gate_{g.name}" for g in gates])
        bound = o.max_sigma_near_horizon_deg if "near_horizon" in res.quality else o.max_sigma_deg
        if res.sigma_deg is not None and res.sigma_deg > bound:
            return not_found(
                None, "imprecise_glare", t, self.frame, self.algorithm, fix_sigma_deg=round(res.sigma_deg, 3)
            )
        share = best.fit.inlier_fraction
        if share < min_rim_share(o.gates, gates):  # a weak rim that nothing else vouches for
            return not_found(
                None, "unvouched_glare", t, self.frame, self.algorithm, rim_share=round(share, 3)
            )
        if res.sigma_deg is not None and res.sigma_deg > max_self_vouched_sigma(o.gates, gates):
            return not_found(  # nor a wide sigma: 1 deg at 3 sigma, with no gate to hold it
                None, "unvouched_glare", t, self.frame, self.algorithm, fix_sigma_deg=round(res.sigma_deg, 3)
            )
        if t is not None:
            self._accepted(best, float(t))
        return res

    # -- internals ---------------------------------------------------------------------------
    def _candidates(
        self, grey: np.ndarray, blobs: list[Blob], peak: float, glare: GlareOptions
    ) -> tuple[list[Candidate], int]:
        """Each blob's inscribed-disk centres fitted and judged (one fit per glare), and how
        many were left unfitted, wholly below the horizon."""
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
                cand = self._measure(grey, x, y, r, peak, glare)
                if cand is not None and cand.reason is not None and cand.fit.one_way_streak:
                    # a saturated cloud below (or above) a dimmed sun may pass for a streak
                    # that leaves one way; if the rim it leaves is not the sun's, drop it
                    cand = self._measure(grey, x, y, r, peak, replace(glare, one_way_streaks=False)) or cand
                elif cand is not None and cand.reason == "incomplete_glare" and cand.fit.short_bloom:
                    # a small glare's short spill up and down its columns: measured as a
                    # bloom both ways, kept only if that rim passes (step 7)
                    bloomed = self._measure(grey, x, y, r, peak, replace(glare, column_bloom=True))
                    cand = bloomed if bloomed is not None and bloomed.reason is None else cand
                if cand is not None:
                    cands.append(cand)
        return cands, low

    def _no_sun(self, cands: list[Candidate], low: int, t: float | None) -> FisheyeResult:
        """The frame's refusal when no candidate was sun-like: the first reason of
        :data:`.visibility.REASON_ORDER` among them (``no_rim`` when none was fitted)."""
        reasons = Counter(c.reason for c in cands)
        if not cands:  # blobs below the horizon explain the frame only when alone
            reasons["below_horizon"] += low
        why = next((r for r in REASON_ORDER if reasons.get(r)), "no_rim")
        extra: dict[str, float | int] = {"candidates": len(cands) + low}
        if cands:  # how wide the widest refused glare was: tens of degrees is the sky's patch
            extra["glare_radius_deg"] = round(max(c.fit.radius_deg for c in cands), 2)
        return not_found(None, why, t, self.frame, self.algorithm, **extra)

    def _choose(
        self, passing: list[Candidate], gates: list[Gate], t: float | None, flags: list[str]
    ) -> Candidate | None:
        """The sun among the candidates that passed every gate: the clearly largest glare;
        among glares of about one size, the one nearest the first gate's centre, or without
        gates the only one that moves like the sun (flagged ``chosen_by_motion``); None when
        nothing tells them apart."""
        o = self.options
        passing.sort(key=lambda c: -c.fit.radius_deg)
        best = passing[0]
        if len(passing) > 1 and passing[1].fit.radius_deg * o.ambiguity_ratio > best.fit.radius_deg:
            close = [c for c in passing if c.fit.radius_deg * o.ambiguity_ratio > best.fit.radius_deg]
            movers = [c for c in close if t is not None and self.history.moves_like_the_sun(t, self._gd(c))]
            if gates:
                g = gates[0]
                return min(passing, key=lambda c: g.distance_deg(self._in(c, g.frame)))
            if len(movers) != 1:
                return None
            flags.append("chosen_by_motion")
            return movers[0]
        return best

    def _off_the_sun(self, cands: list[Candidate], gates: list[Gate]) -> list[float] | None:
        """Where the glare of ``cands`` nearest the sun lies from where the sun must be (the
        ephemeris gate's centre): [along the horizon towards larger azimuth, up] (deg); None
        without that gate, or when it did not refuse that glare (another gate did:
        :mod:`controller.sun.mount_watch` reads only the ephemeris's refusals)."""
        eph = next((g for g in gates if g.name == "ephemeris"), None)
        if eph is None:
            return None
        near = min((self._in(c, "enu") for c in cands), key=eph.distance_deg)  # ENU: the gate needs R
        if eph.distance_deg(near) <= eph.radius_deg:
            return None
        az_s, el_s = (float(v) for v in enu_to_azel(eph.centre))
        az_c, el_c = (float(v) for v in enu_to_azel(near))
        along = ((az_c - az_s + 180.0) % 360.0 - 180.0) * math.cos(math.radians(el_s))
        return [round(along, 3), round(el_c - el_s, 3)]

    def _accepted(self, best: Candidate, t: float) -> None:
        """Keep a detection at ``t``: it anchors the sequence's gate, counts as a sight of the
        site and of the rim's blend when its rim is whole enough, and as the sun's glare seen."""
        if best.fit.inlier_fraction >= self.options.gates.anchor_min_inlier_fraction:
            self._last = (t, self._gd(best))
            self._refused_by_anchor = 0
            self._anchors.append(self._last)
            self._learn_site(t, best)
            if self.blend is not None:
                self.blend.observe(best.fit.axis, best.fit.image_share, best.fit.image_share_sigma, t)
        self.history.accepted(t, best.fit.radius_deg)

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
        return judge(fit, self.options, self.R)

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
        if isinstance(prior, CameraPrior):  # a camera with no orientation, its pose known
            radius = max(g.prior_min_deg, g.prior_k_sigma * prior.sigma_deg + g.base_deg)
            out.append(Gate("prior", np.asarray(prior.d_cam, float), radius, "camera"))
        pd = prior_direction(prior) if self.R is not None and not isinstance(prior, CameraPrior) else None
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
        sigma = glare_sigma(f, o, self.sigma_cal)
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
