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
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..calibration.bundle import CalibrationBundle
from ..errors import ConfigError
from ..sun.types import SunObservation, angle_between_deg, enu_to_azel
from .hotspot import segment_fast, segment_seed
from .imageio import load_grey

ALGORITHMS = ("default", "seed")
METHODS = ("subpixel", "halfvector", "paper")


def mirror_sun_direction(n: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mirror law: sun direction s = 2 (v . n) n - v.

    ``n``: unit outward normal(s); ``v``: unit vector(s) from the surface point TOWARD the
    camera.  (The paper's r = point - camera centre would give -s, the direction the light
    travels.)
    """
    n = np.asarray(n, float)
    v = np.asarray(v, float)
    return 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n - v


def _incidence_frame(s, vbar):
    """(tan of the incidence angle, unit tangent at s in the plane of incidence pointing away
    from the camera direction vbar)."""
    s = np.asarray(s, float)
    vb = np.asarray(vbar, float)
    c = float(np.clip(s @ vb, -1.0, 1.0))
    inc = s * c - vb  # component of -vbar perpendicular to s
    nrm = np.linalg.norm(inc)
    if nrm < 1e-12:
        return 0.0, np.zeros(3)
    theta = 0.5 * math.acos(c)
    return math.tan(theta), inc / nrm


def lobe_tan(s, vbar) -> float:
    return _incidence_frame(s, vbar)[0]


def lobe_correct(s, vbar, coeff_deg: float) -> np.ndarray:
    """Lobe-offset model: the glint's centroid direction is biased by coeff_deg * tan(theta_i)
    away from the camera, in the plane of incidence (the 1/(n.v) and Fresnel factors tilt the
    microfacet lobe); remove it."""
    t, inc = _incidence_frame(s, vbar)
    out = np.asarray(s, float) - math.radians(coeff_deg) * t * inc
    return out / np.linalg.norm(out)


def level_rotation(zenith_model) -> np.ndarray:
    """Smallest rotation taking the model-frame zenith onto +z (Rodrigues about z_t x k)."""
    z = np.asarray(zenith_model, float)
    z = z / np.linalg.norm(z)
    k = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, k)
    s = np.linalg.norm(axis)
    if s < 1e-15:
        return np.eye(3) if z[2] > 0 else np.diag([1.0, -1.0, -1.0])
    ang = math.atan2(s, float(z @ k))
    return cv2.Rodrigues(axis / s * ang)[0]


@dataclass
class HotspotResult:
    image: str | None
    found: bool
    reason: str | None = None
    time: float | None = None
    frame: str = "model"
    az_deg: float | None = None
    el_deg: float | None = None
    sigma_deg: float | None = None
    s_model: np.ndarray | None = None
    s_enu: np.ndarray | None = None
    quality: tuple[str, ...] = ()
    area_px: int = 0
    centre_uv: tuple[float, float] | None = None
    model_az_deg: float | None = None
    model_el_deg: float | None = None
    extra: dict = field(default_factory=dict)

    def observation(self) -> SunObservation | None:
        if not self.found or self.time is None:
            return None
        return SunObservation(time=float(self.time), az_deg=float(self.az_deg),
                              el_deg=float(self.el_deg), sigma_deg=float(self.sigma_deg),
                              frame=self.frame, quality=tuple(self.quality), sensor="hotspot")

    def to_json(self) -> dict:
        d = {"image": self.image, "found": self.found}
        if not self.found:
            d["reason"] = self.reason
        if self.time is not None:
            d["time"] = self.time
        d.update({"frame": self.frame,
                  "az_deg": _r(self.az_deg), "el_deg": _r(self.el_deg),
                  "sigma_deg": _r(self.sigma_deg), "quality": list(self.quality),
                  "area_px": self.area_px})
        if self.centre_uv is not None:
            d["centre_uv"] = [_r(self.centre_uv[0], 3), _r(self.centre_uv[1], 3)]
        if self.s_model is not None:
            d["model_az_deg"] = _r(self.model_az_deg)
            d["model_el_deg"] = _r(self.model_el_deg)
        d.update(self.extra)
        return d


def _r(x, nd=5):
    return None if x is None else round(float(x), nd)


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

    def __init__(self, bundle: CalibrationBundle, *, algorithm: str = "default",
                 method: str = "subpixel", max_blob_fraction: float = 0.02,
                 edge_px: int = 2, sigma_calibration_deg: float = 0.03,
                 end_rule: str = "pseudocode"):
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
        self._build_maps(edge_px)
        z = bundle.zenith()
        self.R_level = level_rotation(z) if z is not None else None
        self.offset = bundle.azimuth_offset_deg
        self.lobe_coeff = bundle.lobe_coeff_deg or 0.0

    # -- per-installation precomputation ------------------------------------------------
    def _build_maps(self, edge_px: int):
        b = self.bundle
        cam = b.camera
        H, W = self.shape
        srf = b.surface
        if srf.kind == "sphere":
            c = np.asarray(srf.center, float)
            r = float(srf.radius)
            min_z = srf.min_z if srf.min_z is not None else c[2]
            box = self._sphere_box(c, r)
            r0, r1, c0, c1 = box
            vv, uu = np.mgrid[r0:r1, c0:c1].astype(np.float64)
            uv = np.stack([uu.ravel(), vv.ravel()], 1).reshape(-1, 1, 2)
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
            xy = cv2.undistortPoints(uv, cam.K, cam.dist_array, None, None, None, crit).reshape(-1, 2)
            dc = np.concatenate([xy, np.ones((xy.shape[0], 1))], 1)
            dc /= np.linalg.norm(dc, axis=1, keepdims=True)
            d = dc @ self.R
            oc = self.C - c
            bb = d @ oc
            rho = np.full(len(d), r)
            poly = srf.radial_poly
            for _ in range(4 if poly is not None else 1):
                disc = bb * bb - (oc @ oc - rho * rho)
                with np.errstate(invalid="ignore"):
                    t = -bb - np.sqrt(disc)
                p = self.C + t[:, None] * d
                if poly is None:
                    break
                from ..calibration.surface import radial_poly_eval

                u = np.nan_to_num((p - c) / np.linalg.norm(p - c, axis=1, keepdims=True))
                hh, gg = radial_poly_eval(u, poly, srf.radial_poly_degree)
                rho = r + hh
            valid = (disc > 0) & (t > 0) & (p[:, 2] >= min_z)
            n = (p - c) / r
            if poly is not None:  # normal of r(u) = radius + h(u): u - grad_t h / r
                u = np.nan_to_num((p - c) / np.linalg.norm(p - c, axis=1, keepdims=True))
                gt = gg - np.sum(gg * u, axis=1, keepdims=True) * u
                n = u - gt / np.maximum(rho, 1e-9)[:, None]
                n /= np.linalg.norm(n, axis=1, keepdims=True)
            v = -d
            area = np.where(valid, t * t / np.clip(np.sum(n * v, 1), 1e-3, None) * dc[:, 2] ** 3, 0)
            shape = (r1 - r0, c1 - c0)
            self.n_map = np.where(valid[:, None], n, 0).reshape(*shape, 3)
            self.v_map = np.where(valid[:, None], v, 0).reshape(*shape, 3)
            self.area_map = area.reshape(shape)
            valid_box = valid.reshape(shape)
            self.jac_map = self._s_jacobian(valid_box)
            self.njac_map = self._n_jacobian(valid_box)
        else:
            from ..calibration.surface import load_cloud

            pts, nrm = load_cloud(srf.cloud)
            if srf.min_z is not None:
                keep = pts[:, 2] >= srf.min_z
                pts, nrm = pts[keep], nrm[keep]
            toward = self.C - pts
            front = np.sum(nrm * toward, 1) > 0
            pts, nrm = pts[front], nrm[front]
            uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), cv2.Rodrigues(self.R)[0], self.tvec,
                                      cam.K, cam.dist_array)
            uv = uv.reshape(-1, 2)
            iu = np.rint(uv[:, 0]).astype(int)
            iv = np.rint(uv[:, 1]).astype(int)
            ok = (iu >= 0) & (iu < W) & (iv >= 0) & (iv < H)
            iu, iv, pts, nrm = iu[ok], iv[ok], pts[ok], nrm[ok]
            r0, r1, c0, c1 = iv.min(), iv.max() + 1, iu.min(), iu.max() + 1
            shape = (r1 - r0, c1 - c0)
            lin = (iv - r0) * shape[1] + (iu - c0)
            cnt = np.bincount(lin, minlength=shape[0] * shape[1]).astype(float)
            nsum = np.stack([np.bincount(lin, nrm[:, k], shape[0] * shape[1]) for k in range(3)], 1)
            psum = np.stack([np.bincount(lin, pts[:, k], shape[0] * shape[1]) for k in range(3)], 1)
            valid = cnt > 0
            n = nsum / np.maximum(np.linalg.norm(nsum, axis=1, keepdims=True), 1e-12)
            p = psum / np.maximum(cnt, 1)[:, None]
            v = self.C - p
            v /= np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
            self.n_map = np.where(valid[:, None], n, 0).reshape(*shape, 3)
            self.v_map = np.where(valid[:, None], v, 0).reshape(*shape, 3)
            self.area_map = cnt.reshape(shape)
            valid_box = valid.reshape(shape)
            box = (r0, r1, c0, c1)
            self.jac_map = self._s_jacobian(valid_box)
            self.njac_map = self._n_jacobian(valid_box)
        self.box = box
        r0, r1, c0, c1 = box
        M = np.zeros((H, W), np.uint8)
        M[r0:r1, c0:c1] = valid_box
        if b.mask is not None:
            user = cv2.imread(str(b.mask), cv2.IMREAD_GRAYSCALE)
            if user is None or user.shape != (H, W):
                raise ConfigError(b.path, "mask", f"a readable {W}x{H} mask image", str(b.mask))
            M &= (user > 0).astype(np.uint8)
        if edge_px > 0:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * edge_px + 1, 2 * edge_px + 1))
            M = cv2.erode(M, k, borderType=cv2.BORDER_CONSTANT, borderValue=0)
        self.mask = M
        self.mask_area = int(M.sum())
        # angular scale: sun-direction degrees per pixel near the globe's centre of view
        self.deg_per_px = self._deg_per_px()

    def _n_jacobian(self, valid):
        """Solid angle of surface normals per pixel |dn/du x dn/dv|."""
        n = self.n_map
        j = np.linalg.norm(np.cross(np.gradient(n, axis=1), np.gradient(n, axis=0)), axis=2)
        ok = cv2.erode(valid.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        med = np.median(j[ok]) if ok.any() else 1.0
        return np.where(ok, j, np.where(valid, med, 0.0))

    def _s_jacobian(self, valid):
        """Solid angle of sun directions per pixel |ds/du x ds/dv| (the mirror map's Jacobian):
        weighting by it makes the centroid one of the glint in sun-direction space."""
        s = mirror_sun_direction(self.n_map, self.v_map)
        su = np.gradient(s, axis=1)
        sv = np.gradient(s, axis=0)
        j = np.linalg.norm(np.cross(su, sv), axis=2)
        j = np.where(valid, j, 0.0)
        # edge pixels of the map have one-sided gradients through invalid neighbours
        ok = cv2.erode(valid.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        med = np.median(j[ok]) if ok.any() else 1.0
        return np.where(ok, j, np.where(valid, med, 0.0))

    def _sphere_box(self, c, r):
        cam = self.bundle.camera
        D = np.linalg.norm(self.C - c)
        if D <= r:
            raise ConfigError(self.bundle.path, "pose", "a camera outside the sphere", float(D))
        a = (c - self.C) / D
        e1 = np.cross(a, [0.0, 0.0, 1.0])
        if np.linalg.norm(e1) < 1e-6:
            e1 = np.cross(a, [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(a, e1)
        ang = np.linspace(0, 2 * np.pi, 180, endpoint=False)
        cc = self.C + a * (D - r * r / D)
        rr = r * math.sqrt(1 - (r / D) ** 2)
        pts = cc + rr * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
        uv, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), cv2.Rodrigues(self.R)[0], self.tvec,
                                  cam.K, cam.dist_array)
        uv = uv.reshape(-1, 2)
        H, W = self.shape
        c0 = max(int(np.floor(uv[:, 0].min())) - 3, 0)
        c1 = min(int(np.ceil(uv[:, 0].max())) + 4, W)
        r0 = max(int(np.floor(uv[:, 1].min())) - 3, 0)
        r1 = min(int(np.ceil(uv[:, 1].max())) + 4, H)
        if c1 <= c0 or r1 <= r0:
            raise ConfigError(self.bundle.path, "pose", "a pose that puts the surface in view")
        return r0, r1, c0, c1

    def _deg_per_px(self) -> float:
        n = self.n_map
        valid = np.linalg.norm(n, axis=2) > 0
        if valid.sum() < 4:
            return 1.0
        dn = np.linalg.norm(np.diff(n, axis=1), axis=2)
        ok = valid[:, 1:] & valid[:, :-1]
        return float(2 * np.degrees(np.median(dn[ok])))

    # -- per frame ------------------------------------------------------------------------
    def estimate_file(self, path: str | Path, t: float | None = None) -> HotspotResult:
        img, reason = load_grey(path)
        if img is None:
            return HotspotResult(image=str(path), found=False, reason=reason, time=t,
                                 frame="enu" if self._has_enu else "model", quality=(reason,))
        res = self.estimate_image(img, t)
        res.image = str(path)
        return res

    def estimate_image(self, image: np.ndarray, t: float | None = None) -> HotspotResult:
        out = HotspotResult(image=None, found=False, time=t,
                            frame="enu" if self._has_enu else "model")
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
            out.quality = (seg.reason,)
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
        r0, r1, c0, c1 = seg.roi
        hm = seg.roi_mask
        # at the mask's edge: the grown hotspot leaves the mask
        grown = cv2.dilate(hm, np.ones((3, 3), np.uint8))
        if np.any(grown & (1 - self.mask[r0:r1, c0:c1])):
            flags.append("at_mask_edge")
            out.reason = "at_mask_edge"
            out.quality = tuple(flags)
            return out
        s, centre, spread, neff, vbar = self._direction(image, seg)
        if s is not None:
            out.extra["tan_incidence"] = _r(lobe_tan(s, vbar))
            out.extra["v_bar"] = [_r(x, 7) for x in vbar]
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
            out.extra["levelled_el_deg"] = _r(el_l)
            out.extra["levelled_az_deg"] = _r(az_l)
            if el_l < -2.0:
                out.reason = "below_horizon"
                out.quality = tuple(flags + ["below_horizon"])
                return out
            if self.offset is not None:
                az = (float(az_l) - self.offset) % 360.0
                el = float(el_l)
                out.s_enu = np.array([math.cos(math.radians(el)) * math.sin(math.radians(az)),
                                      math.cos(math.radians(el)) * math.cos(math.radians(az)),
                                      math.sin(math.radians(el))])
        out.az_deg, out.el_deg = az, el
        sig_centroid = 0.15 * self.deg_per_px  # ~0.15 px centring error
        out.sigma_deg = float(math.sqrt(sig_centroid ** 2 + (spread / math.sqrt(max(neff, 1))) ** 2
                                        + self.sigma_cal ** 2))
        out.found = True
        out.quality = tuple(flags)
        out.centre_uv = centre
        out.extra["i_opt"] = seg.i_opt
        return out

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
        spread = float(np.sqrt((w * ang ** 2).sum() / w.sum()))
        neff = float(w.sum() ** 2 / (w ** 2).sum())
        vbar = (w[:, None] * v[ok]).sum(0)
        vbar /= np.linalg.norm(vbar)
        return s, centre, spread, neff, vbar
