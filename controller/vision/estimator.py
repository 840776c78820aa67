"""Hotspot sun sensor: image + calibration bundle -> SunObservation.

Per pixel of the surface mask the estimator knows (once per installation) the surface point,
its outward unit normal n and the unit vector v from the point TOWARD the camera centre.
For the glint pixels the mirror law gives the sun direction s = 2 (v . n) n - v, and the
weighted mean of the s_i is the measurement (paper 000, eqs. 1, 5-7).

Algorithms (segmentation): ``seed`` = Algorithm 1 literally on the full frame; ``default``
= the same mask on a window (see :mod:`controller.vision.hotspot`).
Direction methods: ``paper`` = quadratic grey weights (GV - min)^2 over H, each pixel counted
by the surface area it covers (the paper's uniformly spread model points); ``subpixel``
(default) = soft-threshold weights over H grown by 2 px, so edge pixels that are partly
covered by the glint move the centre by fractions of a pixel.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from ..calibration.bundle import CalibrationBundle
from ..errors import ConfigError
from ..sun.types import angle_between_deg, enu_to_azel
from .hotspot import segment_fast, segment_seed
from .imageio import load_grey
from .mirror import level_rotation, lobe_correct, lobe_tan, mirror_sun_direction
from .result import HotspotResult, rounded
from .surface_map import SurfaceMap

ALGORITHMS = ("default", "seed")
METHODS = ("subpixel", "halfvector", "paper")


class HotspotEstimator:
    """Estimate the sun from images of the convex surface with one calibration bundle.

    Parameters
    ----------
    bundle : CalibrationBundle (camera, surface and pose required; level, azimuth optional)
    algorithm : "default" (fast, identical mask) or "seed" (Algorithm 1 literally)
    method : "subpixel" (default) or "paper" (quadratic grey weights over H)
    max_blob_fraction : a hotspot larger than this fraction of the mask means overexposure
    edge_px : mask erosion at the silhouette (pixels mixing globe and background)
    """

    def __init__(
        self,
        bundle: CalibrationBundle,
        *,
        algorithm: str = "default",
        method: str = "subpixel",
        max_blob_fraction: float = 0.02,
        edge_px: int = 2,
        sigma_calibration_deg: float = 0.03,
        end_rule: str = "pseudocode",
    ):
        if algorithm not in ALGORITHMS:
            raise ConfigError(None, "algorithm", f"one of {ALGORITHMS}", algorithm)
        if method not in METHODS:
            raise ConfigError(None, "method", f"one of {METHODS}", method)
        bundle.require("surface")
        bundle.require("pose")
        self.bundle = bundle
        self.algorithm = algorithm
        self.method = method
        self.end_rule = end_rule
        self.max_blob_fraction = max_blob_fraction
        self.sigma_cal = sigma_calibration_deg
        cam = bundle.camera
        self.shape = (cam.height, cam.width)
        rvec, tvec = bundle.solved_pose()
        self.R = cv2.Rodrigues(np.asarray(rvec, float))[0]
        self.tvec = np.asarray(tvec, float)
        self.C = -self.R.T @ self.tvec
        self.maps = maps = SurfaceMap(bundle, self.R, self.tvec, edge_px)
        self.n_map, self.v_map, self.box = maps.n_map, maps.v_map, maps.box
        self.area_map, self.jac_map, self.njac_map = maps.area_map, maps.jac_map, maps.njac_map
        self.mask, self.mask_area, self.deg_per_px = maps.mask, maps.mask_area, maps.deg_per_px
        z = bundle.zenith()
        self.R_level = level_rotation(z) if z is not None else None
        self.offset = bundle.azimuth_offset_deg
        self.lobe_coeff = bundle.lobe_coeff_deg or 0.0

    # -- per frame ------------------------------------------------------------------------
    def estimate_file(self, path: str | Path, t: float | None = None) -> HotspotResult:
        img, reason = load_grey(path)
        if img is None:
            return HotspotResult(
                image=str(path),
                found=False,
                reason=reason,
                time=t,
                frame="enu" if self._has_enu else "model",
                quality=(reason or "unreadable",),
            )
        res = self.estimate_image(img, t)
        res.image = str(path)
        return res

    def estimate_image(self, image: np.ndarray, t: float | None = None) -> HotspotResult:
        out = HotspotResult(image=None, found=False, time=t, frame="enu" if self._has_enu else "model")
        if image is None or image.ndim != 2 or image.shape != self.shape:
            got = None if image is None else tuple(image.shape)
            out.reason = "size_mismatch"
            out.extra["expected_shape"] = list(self.shape)
            out.extra["got_shape"] = list(got) if got else None
            return out
        if image.dtype != np.uint8:
            out.reason = "not_8bit"
            return out
        seg_fn = segment_seed if self.algorithm == "seed" else segment_fast
        seg = seg_fn(image, self.mask, end_rule=self.end_rule)
        if not seg.found:
            out.reason = seg.reason
            out.quality = (seg.reason or "not found",)
            out.extra["i_max"] = seg.i_max
            return out
        out.area_px = seg.area
        flags = []
        if seg.n_candidates > 1:
            flags.append("several_candidates")
        if seg.area == 0:
            out.reason = "no_glint"
            out.quality = ("no_glint",)
            return out
        if seg.area > self.max_blob_fraction * self.mask_area:
            out.reason = "saturated_blob_too_large"
            out.quality = tuple(flags + ["saturated_blob_too_large"])
            return out
        distinct = self._distinct(image, seg)
        if distinct:
            out.reason = distinct
            out.quality = tuple(flags + [distinct])
            return out
        assert seg.roi is not None and seg.roi_mask is not None  # a found segmentation has them
        r0, r1, c0, c1 = seg.roi
        hm = seg.roi_mask
        # at the mask's edge: the grown hotspot leaves the mask
        grown = np.asarray(cv2.dilate(hm, np.ones((3, 3), np.uint8)), np.uint8)
        if np.any(grown & (1 - self.mask[r0:r1, c0:c1])):
            flags.append("at_mask_edge")
            out.reason = "at_mask_edge"
            out.quality = tuple(flags)
            return out
        s, centre, spread, neff, vbar = self._direction(image, seg)
        if s is not None:
            out.extra["tan_incidence"] = rounded(lobe_tan(s, vbar))
            out.extra["v_bar"] = [rounded(x, 7) for x in vbar]
            if self.lobe_coeff:
                s = lobe_correct(s, vbar, self.lobe_coeff)
        if s is None:
            out.reason = "no_surface_geometry"
            out.quality = tuple(flags + ["no_surface_geometry"])
            return out
        out.s_model = s
        az_m, el_m = enu_to_azel(s)
        out.model_az_deg, out.model_el_deg = float(az_m), float(el_m)
        az, el = float(az_m), float(el_m)
        if self.R_level is not None:
            sl = self.R_level @ s
            az_l, el_l = enu_to_azel(sl)
            out.extra["levelled_el_deg"] = rounded(float(el_l))
            out.extra["levelled_az_deg"] = rounded(float(az_l))
            if el_l < -2.0:
                out.reason = "below_horizon"
                out.quality = tuple(flags + ["below_horizon"])
                return out
            if self.offset is not None:
                az = (float(az_l) - self.offset) % 360.0
                el = float(el_l)
                out.s_enu = np.array(
                    [
                        math.cos(math.radians(el)) * math.sin(math.radians(az)),
                        math.cos(math.radians(el)) * math.cos(math.radians(az)),
                        math.sin(math.radians(el)),
                    ]
                )
        out.az_deg, out.el_deg = az, el
        sig_centroid = 0.15 * self.deg_per_px  # ~0.15 px centring error
        out.sigma_deg = float(
            math.sqrt(sig_centroid**2 + (spread / math.sqrt(max(neff, 1))) ** 2 + self.sigma_cal**2)
        )
        out.found = True
        out.quality = tuple(flags)
        out.centre_uv = centre
        out.extra["i_opt"] = seg.i_opt
        return out

    #: A glint must stand out of the painted surface around it by this many robust sigmas
    #: of that surface, and by ``MIN_CONTRAST_DN`` at least: a specular image of the sun is
    #: orders of magnitude brighter than the diffuse black paint, noise is not.
    MIN_CONTRAST_SIGMAS = 6.0
    MIN_CONTRAST_DN = 20.0
    #: More separate bright components than this is not one glint (noise, a lit surface).
    MAX_CANDIDATES = 8

    def _distinct(self, image: np.ndarray, seg) -> str | None:
        """Reason to refuse a segmentation that is not a glint on a dark surface, or None."""
        if seg.n_candidates > self.MAX_CANDIDATES:
            return "ambiguous_bright_spots"
        r0, r1, c0, c1 = seg.roi
        H, W = self.shape
        pad = 24
        R0, R1, C0, C1 = max(r0 - pad, 0), min(r1 + pad, H), max(c0 - pad, 0), min(c1 + pad, W)
        blob = np.zeros((R1 - R0, C1 - C0), np.uint8)
        blob[r0 - R0 : r1 - R0, c0 - C0 : c1 - C0] = seg.roi_mask
        near = cv2.dilate(blob, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11)))
        far = cv2.dilate(blob, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (41, 41)))
        ring = (far > 0) & (near == 0) & (self.mask[R0:R1, C0:C1] > 0)
        if ring.sum() < 20:
            return None  # no surface around to compare with
        around = image[R0:R1, C0:C1][ring].astype(np.float64)
        med = float(np.median(around))
        sigma = max(1.4826 * float(np.median(np.abs(around - med))), 1.0)
        if seg.i_max - med < max(self.MIN_CONTRAST_SIGMAS * sigma, self.MIN_CONTRAST_DN):
            return "no_distinct_glint"
        return None

    @staticmethod
    def _halfvector_centre(n, v, w, s, iters: int = 8):
        """Sun direction s for which the glint's normals are centred on the half vectors
        h_i(s) = unit(v_i + s): the microfacet lobe is symmetric about h in normal space, so
        this removes the bias of averaging mirror directions across a lobe seen obliquely."""
        W = w.sum()
        for _ in range(iters):
            hv = v + s
            hn = np.linalg.norm(hv, axis=1, keepdims=True)
            h = hv / hn
            r = (w[:, None] * (n - h)).sum(0) / W
            # dh/ds = (I - h h^T) / |v + s|  ->  ds = |v + s| r (tangential)
            step = float(np.average(hn[:, 0], weights=w)) * r
            step -= (step @ s) * s
            s = s + step
            s /= np.linalg.norm(s)
            if np.linalg.norm(step) < 1e-10:
                break
        return s

    @property
    def _has_enu(self) -> bool:
        return self.R_level is not None and self.offset is not None

    def _direction(self, image, seg):
        r0, r1, c0, c1 = seg.roi
        br0, br1, bc0, bc1 = self.box
        hm = seg.roi_mask
        img = image[r0:r1, c0:c1].astype(np.float64)
        if self.method == "paper":
            sel = hm > 0
            gv = img[sel]
            lo, hi = gv.min(), gv.max()
            w = ((gv - lo) / (hi - lo)) ** 2 if hi > lo else np.ones_like(gv)
        else:
            region = cv2.dilate(hm, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
            region &= self.mask[r0:r1, c0:c1]
            sel = region > 0
            gv = img[sel]
            floor = 0.5 * (seg.i_opt + seg.i_min)
            top = max(float(seg.i_max), floor + 1)
            w = np.clip((gv - floor) / (top - floor), 0.0, 1.0)
        rr, cc = np.nonzero(sel)
        rr = rr + r0
        cc = cc + c0
        inside = (rr >= br0) & (rr < br1) & (cc >= bc0) & (cc < bc1)
        rr, cc, w = rr[inside], cc[inside], w[inside]
        n = self.n_map[rr - br0, cc - bc0]
        v = self.v_map[rr - br0, cc - bc0]
        if self.method == "paper":
            a = self.area_map[rr - br0, cc - bc0]
        elif self.method == "halfvector":
            a = self.njac_map[rr - br0, cc - bc0]
        else:
            a = self.jac_map[rr - br0, cc - bc0]
        ok = a > 0
        if not ok.any():
            return None, None, 0.0, 0, None
        w = w[ok] * a[ok]
        if w.sum() <= 0:
            w = a[ok]
        si = mirror_sun_direction(n[ok], v[ok])
        s = (w[:, None] * si).sum(0)
        s /= np.linalg.norm(s)
        if self.method == "halfvector":
            s = self._halfvector_centre(n[ok], v[ok], w, s)
        centre = (float((w * cc[ok]).sum() / w.sum()), float((w * rr[ok]).sum() / w.sum()))
        ang = angle_between_deg(si, s)
        spread = float(np.sqrt((w * ang**2).sum() / w.sum()))
        neff = float(w.sum() ** 2 / (w**2).sum())
        vbar = (w[:, None] * v[ok]).sum(0)
        vbar /= np.linalg.norm(vbar)
        return s, centre, spread, neff, vbar
