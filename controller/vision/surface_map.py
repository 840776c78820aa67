"""Per-installation maps of the surface seen by the camera (built once per bundle).

For every pixel of the surface in view: the surface point's outward unit normal ``n_map``,
the unit vector toward the camera ``v_map``, the surface area per pixel ``area_map`` and
the Jacobians of the mirror map (solid angle of sun directions ``jac_map`` and of normals
``njac_map`` per pixel), inside the pixel box ``box = (r0, r1, c0, c1)``; the usable
``mask`` of the whole frame (eroded at the silhouette, ANDed with the bundle's mask).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..calibration.bundle import CalibrationBundle
from ..errors import ConfigError
from .mirror import mirror_sun_direction


class SurfaceMap:
    """Maps of one installation (bundle with camera, surface and pose).

    Parameters
    ----------
    bundle : CalibrationBundle
    R, tvec : model -> camera rotation matrix and translation (m)
    edge_px : mask erosion at the silhouette (pixels mixing surface and background)
    """

    def __init__(self, bundle: CalibrationBundle, R: np.ndarray, tvec: np.ndarray, edge_px: int = 2):
        self.bundle = bundle
        cam = bundle.camera
        self.shape = (cam.height, cam.width)
        self.R = R
        self.tvec = tvec
        self.C = -R.T @ tvec
        self._build(edge_px)

    def _build(self, edge_px: int) -> None:
        b = self.bundle
        cam = b.camera
        H, W = self.shape
        srf = b.surface
        assert srf is not None  # the estimator requires [surface]
        box: tuple[int, int, int, int]
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
            passes = 4 if poly is not None else 1
            for step in range(passes):
                disc = bb * bb - (oc @ oc - rho * rho)
                with np.errstate(invalid="ignore"):
                    t = -bb - np.sqrt(disc)
                p = self.C + t[:, None] * d
                if poly is None:
                    break
                from ..calibration.surface import radial_poly_eval

                u = np.nan_to_num((p - c) / np.linalg.norm(p - c, axis=1, keepdims=True))
                # the gradient (the normal) of the last pass only: the others place the point
                hh, gg = radial_poly_eval(u, poly, int(srf.radial_poly_degree or 0), grad=step == passes - 1)
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

            assert srf.cloud is not None  # the schema requires it for a cloud
            pts, nrm = load_cloud(srf.cloud)
            if srf.min_z is not None:
                keep = pts[:, 2] >= srf.min_z
                pts, nrm = pts[keep], nrm[keep]
            toward = self.C - pts
            front = np.sum(nrm * toward, 1) > 0
            pts, nrm = pts[front], nrm[front]
            projected, _ = cv2.projectPoints(
                pts.reshape(-1, 1, 3), cv2.Rodrigues(self.R)[0], self.tvec, cam.K, cam.dist_array
            )
            uvc = np.asarray(projected).reshape(-1, 2)
            iu = np.rint(uvc[:, 0]).astype(int)
            iv = np.rint(uvc[:, 1]).astype(int)
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
            M = M & (user > 0).astype(np.uint8)
        if edge_px > 0:
            k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * edge_px + 1, 2 * edge_px + 1))
            M = np.asarray(cv2.erode(M, k, borderType=cv2.BORDER_CONSTANT, borderValue=0), np.uint8)
        if not M.any():  # every frame would be `empty_mask`: say why once, at load
            raise ConfigError(
                b.path,
                "pose",
                "a camera that sees the surface (none of it is in the image: behind the camera?)",
            )
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
        uv, _ = cv2.projectPoints(
            pts.reshape(-1, 1, 3), cv2.Rodrigues(self.R)[0], self.tvec, cam.K, cam.dist_array
        )
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
