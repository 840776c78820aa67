"""The fourth renderer's scene: a frame of its world at a time, and its truth.

See :mod:`benchmarks.fisheye_fourth_world` for the physics.  Rendering imports neither
``hil`` nor ``controller``.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from .fisheye_fourth_world import (
    AER_G,
    AER_W,
    CIE,
    CLOUD_G,
    CORE_SIGMA,
    F0,
    FW,
    GLARE_A1,
    GLARE_A2,
    GLARE_S1,
    GLARE_S2,
    GROUND_ALB,
    GROUND_COL,
    LIMB_U,
    PP_OFF,
    READ_E,
    SKY_BLUE,
    SMEAR,
    SUN_RAD,
    TAU_A,
    TAU_R,
    THETA_MAX,
    CloudSpec,
    Look,
    airmass,
    build_pose,
    enu_of,
    fbm_field,
    hg,
    kb_fit,
    lens_r_unit,
    rotation_about,
    srgb_encode,
    sun_position,
)


class FourthScene:
    TILE_KM = 48.0
    TILE_N = 512

    def __init__(
        self,
        look: Look,
        site=(-33.92, 18.42, 20.0),
        clouds: CloudSpec | None = None,
        distractors: bool = False,
        seed: int = 0,
    ):
        self.look = look
        self.site = tuple(float(v) for v in site)
        self.clouds = clouds
        self.distractors = bool(distractors)
        self.seed = int(seed)
        W, H = self.look.width, self.look.height
        self.W, self.H = W, H
        self.s = W / 640.0
        self.f = 0.48 * H / float(lens_r_unit(THETA_MAX))
        self.cx = (W - 1) / 2.0 + PP_OFF[0] * self.s
        self.cy = (H - 1) / 2.0 + PP_OFF[1] * self.s
        self.M = build_pose()
        self.kb_f, self.kb_D, self.kb_resid = kb_fit(self.f)
        # inverse lens LUT
        self._th_lut = np.linspace(0.0, math.radians(100.0), 40001)
        self._r_lut = self.f * lens_r_unit(self._th_lut)
        # per-pixel geometry
        u = np.arange(W, dtype=np.float64)
        v = np.arange(H, dtype=np.float64)
        self.uu, self.vv = np.meshgrid(u, v)
        self.dirs, self.theta = self.unproject(self.uu, self.vv)
        self.el = np.degrees(np.arcsin(np.clip(self.dirs[..., 2], -1, 1)))
        self.az = np.degrees(np.arctan2(self.dirs[..., 0], self.dirs[..., 1])) % 360.0
        r = np.hypot(self.uu - self.cx, self.vv - self.cy)
        rmax = self.f * float(lens_r_unit(THETA_MAX))
        self.circle = np.clip(rmax + 0.5 - r, 0.0, 1.0)  # soft 1-px edge
        self.zen_uv = self.project(np.array([0.0, 0.0, 1.0]))
        # static ground texture
        rng = np.random.default_rng(12345 + self.seed)
        az_i = (self.az / 360.0 * 2048).astype(np.int32) % 2048
        el_i = np.clip((-self.el) * 20, 0, 1023).astype(np.int32)
        coarse = cv2.GaussianBlur(rng.standard_normal((1024, 2048)).astype(np.float32), (0, 0), 12)
        coarse /= coarse.std() + 1e-9
        fine = rng.standard_normal((1024, 2048)).astype(np.float32)
        self.ground_tex = (
            1
            + 0.12 * np.clip(coarse[el_i, az_i], -2.5, 2.5) / 2.5
            + 0.05 * np.clip(fine[el_i, az_i], -2, 2) / 2
        )
        # clouds
        if clouds is not None:
            crng = np.random.default_rng([7331, int(clouds.seed)])
            n = fbm_field(self.TILE_N, self.TILE_KM, 3.3, 1 / 8.0, crng)
            cover = float(np.clip(clouds.cover, 0.0, 1.0))
            thr = np.quantile(n, 1 - cover) if cover > 0 else n.max() + 1
            top = np.quantile(n, 0.999)
            ramp = 0.12
            sgl = np.clip((n - thr) / max(top - thr, 1e-6), 0, 1)
            tau = np.where(
                n >= thr, 0.3 * (40 / 0.3) ** (sgl**0.8), 0.3 * np.clip((n - thr + ramp) / ramp, 0, 1)
            )
            self.tau_tile = tau.astype(np.float32)
            pad = 16
            tp = np.pad(self.tau_tile, pad, mode="wrap")
            self.tau_tile_blur = np.ascontiguousarray(cv2.GaussianBlur(tp, (0, 0), 4.0)[pad:-pad, pad:-pad])
            mu = np.maximum(self.dirs[..., 2], 1e-6)
            Z = np.arccos(np.clip(self.dirs[..., 2], -1, 1))
            up = self.dirs[..., 2] > math.cos(math.radians(89.5))
            hx = np.where(up, clouds.base_km * np.tan(np.minimum(Z, math.radians(89.5))), 0.0)
            horiz = np.hypot(self.dirs[..., 0], self.dirs[..., 1]) + 1e-12
            self.c_x = hx * self.dirs[..., 0] / horiz
            self.c_y = hx * self.dirs[..., 1] / horiz
            self.c_dist = clouds.base_km / mu
            self.c_up = up
            self.c_mu = np.maximum(self.dirs[..., 2], 0.05)
            wd = math.radians(clouds.wind_dir_deg)
            self.c_vel = -clouds.wind_mps / 1000.0 * np.array([math.sin(wd), math.cos(wd)])  # km/s, towards

    # -- geometry ---------------------------------------------------------------
    def unproject(self, u, v):
        du, dv = np.asarray(u, float) - self.cx, np.asarray(v, float) - self.cy
        r = np.hypot(du, dv)
        th = np.interp(r, self._r_lut, self._th_lut)
        sr = np.where(r > 0, np.sin(th) / np.maximum(r, 1e-12), 0.0)
        dc = np.stack([du * sr, dv * sr, np.cos(th)], -1)
        return dc @ self.M.T, th

    def project(self, d_enu):
        d = np.asarray(d_enu, float)
        dc = d @ self.M  # = (M^T d)
        dc = dc / np.linalg.norm(dc, axis=-1, keepdims=True)
        th = np.arccos(np.clip(dc[..., 2], -1, 1))
        rr = self.f * lens_r_unit(th)
        ph = np.arctan2(dc[..., 1], dc[..., 0])
        return np.stack([self.cx + rr * np.cos(ph), self.cy + rr * np.sin(ph)], -1)

    def bundle(self) -> dict:
        b = {
            "camera": {
                "model": "fisheye",
                "width": self.W,
                "height": self.H,
                "fx": self.kb_f,
                "fy": self.kb_f,
                "cx": self.cx,
                "cy": self.cy,
                "dist": list(self.kb_D),
            },
            "orientation": {"enu_from_camera": self.M.tolist()},
            "site": {"latitude": self.site[0], "longitude": self.site[1], "altitude": self.site[2]},
        }
        if self.look.tone == "srgb":
            b["radiometry"] = {"response": "srgb"}
        return b

    # -- radiometry ---------------------------------------------------------
    def _cloud_tau(self, t, x, y, blur=None):
        shift = self.c_vel * t
        scale = self.TILE_N / self.TILE_KM
        mx = np.mod((x - shift[0]) * scale, self.TILE_N).astype(np.float32)
        my = np.mod((-(y - shift[1])) * scale, self.TILE_N).astype(np.float32)
        tile = self.tau_tile if blur is None else blur
        return cv2.remap(tile, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)

    def _sky(self, s_enu, el_s, Tc_sun):
        """clear sky + aureole + haze + ground (H,W,3 RGB radiance), plus helpers."""
        d = self.dirs
        gs = math.radians(max(el_s, 0.0))
        Zs = math.pi / 2 - gs
        cosZ = np.clip(d[..., 2], 0.0, 1.0)
        cosx = np.clip(d @ s_enu, -1, 1)
        chi = np.arccos(cosx)
        a, b, c, dd, e = CIE["a"], CIE["b"], CIE["c"], CIE["d"], CIE["e"]
        phi = 1 + a * np.exp(b / np.maximum(cosZ, 0.01))
        phi0 = 1 + a * math.exp(b)
        fi = 1 + c * (np.exp(dd * chi) - math.exp(dd * math.pi / 2)) + e * cosx**2
        fzs = 1 + c * (math.exp(dd * Zs) - math.exp(dd * math.pi / 2)) + e * math.cos(Zs) ** 2
        Lz = ((math.sin(gs) + 0.08) / (math.sin(math.radians(60)) + 0.08)) ** 0.7
        rel = (fi * phi) / (fzs * phi0) * Lz
        el = self.el
        wh = 0.75 * np.exp(-np.maximum(el, 0) / 7.0)
        ws = 0.6 * np.exp(-np.degrees(chi) / 12.0)
        w = 1 - (1 - wh) * (1 - ws)
        col = SKY_BLUE[None, None, :] * (1 - w[..., None]) + w[..., None]
        L = rel[..., None] * col
        # aerosol aureole (single scattering)
        m_s = float(airmass(el_s))
        T_atm = np.exp(-(TAU_R + TAU_A) * m_s)
        mus = max(math.sin(gs), 0.02)
        muv = np.maximum(d[..., 2], 0.02)[..., None]
        P = hg(cosx, AER_G)[..., None]
        ta = TAU_A[None, None, :]
        diff = mus - muv
        near = np.abs(diff) < 1e-4
        safe = np.where(near, 1.0, diff)
        geo = np.where(
            near, ta / muv * np.exp(-ta / muv), mus / safe * (np.exp(-ta / mus) - np.exp(-ta / muv))
        )
        Tr_s = np.exp(-TAU_R * m_s)  # Rayleigh dims the beam feeding the aerosol
        L = L + F0 * AER_W * P / (4 * math.pi) * geo * Tr_s[None, None, :]
        # horizon haze band
        Lh = np.mean(L, -1, keepdims=True)
        band = 0.9 * np.exp(-0.5 * ((el - 0.3) / 0.6) ** 2)[..., None]
        L = L + band * Lh * np.array([0.97, 0.99, 1.0])
        # ground
        E_h = F0 * float(np.mean(T_atm)) * Tc_sun * math.sin(gs) + math.pi * 1.6 * Lz
        Lg = GROUND_ALB * E_h / math.pi * GROUND_COL[None, None, :] * self.ground_tex[..., None]
        Lg = Lg + 0.9 * np.exp(-0.5 * ((el - 0.3) / 0.6) ** 2)[..., None] * Lh  # haze in front of ground
        gw = np.clip((el + 0.1) / 0.2, 0, 1)[..., None]
        L = gw * L + (1 - gw) * Lg
        return L, cosx, T_atm, Lz, mus

    def _zenith_rgb(self, s_enu, el_s):
        gs = math.radians(max(el_s, 0.0))
        Zs = math.pi / 2 - gs
        Lz = ((math.sin(gs) + 0.08) / (math.sin(math.radians(60)) + 0.08)) ** 0.7
        chi = Zs
        ws = 0.6 * math.exp(-math.degrees(chi) / 12.0)
        wh = 0.75 * math.exp(-90 / 7.0)
        w = 1 - (1 - wh) * (1 - ws)
        col = SKY_BLUE * (1 - w) + w
        L = Lz * col
        m_s = float(airmass(el_s))
        mus = max(math.sin(gs), 0.02)
        P = float(hg(math.cos(chi), AER_G))
        muv = 1.0
        if abs(mus - muv) < 1e-4:
            geo = TAU_A / muv * np.exp(-TAU_A / muv)
        else:
            geo = mus / (mus - muv) * (np.exp(-TAU_A / mus) - np.exp(-TAU_A / muv))
        L = L + F0 * AER_W * P / (4 * math.pi) * geo * np.exp(-TAU_R * m_s)
        return L

    def _exposure(self, Lzen_rgb):
        target = self.look.zenith_grey
        if self.look.tone == "srgb":
            lo, hi = 0.0, 10.0 * FW / float(np.min(Lzen_rgb))
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                g = np.mean(255 * srgb_encode(mid * Lzen_rgb / FW))
                lo, hi = (mid, hi) if g < target else (lo, mid)
            return 0.5 * (lo + hi)
        return target / 255.0 * FW / float(np.mean(Lzen_rgb))

    # -- frame --------------------------------------------------------------
    def truth(self, t_posix: float) -> dict:
        az, el = sun_position(t_posix, self.site)
        az, el = float(az[0]), float(el[0])
        s = enu_of(az, el)
        T = 1.0
        if self.clouds is not None and el > 0:
            tau = self._sun_tau(t_posix, s, el)
            T = math.exp(-tau / max(math.sin(math.radians(el)), 0.05))
        vis = "hidden" if (el < 3 or T < 0.05) else ("visible" if T >= 0.9 else "dimmed")
        return {"az_deg": az, "el_deg": el, "sun_enu": s, "transmittance": T, "visibility": vis}

    def _sun_tau(self, t, s, el):
        h = self.clouds.base_km
        Z = math.radians(90 - el)
        rho = h * math.tan(min(Z, math.radians(89.5)))
        hz = math.hypot(s[0], s[1]) + 1e-12
        x = np.array([[rho * s[0] / hz]], np.float64)
        y = np.array([[rho * s[1] / hz]], np.float64)
        return float(self._cloud_tau(t, x, y)[0, 0])

    def frame(self, t_posix: float):
        t = float(t_posix)
        tr = self.truth(t)
        el_s, s = tr["el_deg"], tr["sun_enu"]
        T = tr["transmittance"]
        L, cosx, T_atm, Lz, mus = self._sky(s, el_s, T)
        # clouds
        if self.clouds is not None:
            tau = self._cloud_tau(t, self.c_x, self.c_y)
            far = self.c_dist > 10.0
            if far.any():
                tb = self._cloud_tau(t, self.c_x, self.c_y, self.tau_tile_blur)
                wb = np.clip((self.c_dist - 10.0) / 20.0, 0, 1)
                tau = tau * (1 - wb) + tb * wb
            tau = np.where(self.c_up, tau, 0.0)
            tau_v = tau / self.c_mu
            cov = 1 - np.exp(-tau_v)
            wfar = np.where(self.c_up, np.exp(-self.c_dist / 60.0), 0.0)
            L_ref = (F0 * float(np.mean(T_atm)) * mus + 1.6 * math.pi * Lz) / math.pi
            Ldiff = L_ref * cov / (1 + 0.75 * (1 - CLOUD_G) * tau)
            thick = np.clip(tau / 40.0, 0, 1)
            ccol = np.stack([0.97 - 0.05 * thick, 0.99 - 0.02 * thick, 1.03 + 0.03 * thick], -1)
            Lfwd = (F0 * hg(cosx, CLOUD_G) / (4 * math.pi) * cov * np.exp(-0.5 * (tau_v + tau / mus)))[
                ..., None
            ] * T_atm[None, None, :]
            Lc = Ldiff[..., None] * ccol + Lfwd
            wf = wfar[..., None]
            L = L * (1 - wf * cov[..., None]) + wf * Lc
        Lzen = self._zenith_rgb(s, el_s)
        if el_s > -1.0:  # the metering also sees the veiling glare at the zenith
            dz = float(np.hypot(*(self.zen_uv - self.project(s))))
            Lzen = Lzen + self._wing(dz) * self.look.sun_radiance * T_atm * T
        X = self._exposure(Lzen)
        q = L * (X * self.circle)[..., None]  # electrons, RGB
        # sun disk + glare
        if el_s > -1.0:
            self._add_sun(q, s, el_s, T, X, T_atm)
        if self.distractors:
            self._add_distractors(q, t, s, el_s, T)
        img = self._sensor(q, t)
        return img, tr

    def _add_sun(self, q, s, el_s, T, X, T_atm):
        uv = self.project(s)
        Ldisk = self.look.sun_radiance * T_atm * T  # RGB mean disk radiance
        sc = self.s
        # local patch
        dr = self.f * SUN_RAD * 1.2 + 4 * CORE_SIGMA * sc + 3
        u0, v0 = int(math.floor(uv[0] - dr)), int(math.floor(uv[1] - dr))
        u1, v1 = int(math.ceil(uv[0] + dr)), int(math.ceil(uv[1] + dr))
        n = 9
        off = (np.arange(n) + 0.5) / n - 0.5
        pu = np.arange(u0, u1 + 1)
        pv = np.arange(v0, v1 + 1)
        su = (pu[None, :, None, None] + off[None, None, None, :]) + 0 * off[None, None, :, None]
        sv = (pv[:, None, None, None] + off[None, None, :, None]) + 0 * off[None, None, None, :]
        su, sv = np.broadcast_arrays(su, sv)
        dd, _ = self.unproject(su, sv)
        ang = np.arccos(np.clip(dd @ s, -1, 1))
        mu = np.sqrt(np.clip(1 - (ang / SUN_RAD) ** 2, 0, 1))
        limb = np.where(ang < SUN_RAD, (1 - LIMB_U * (1 - mu)) / (1 - LIMB_U / 3), 0.0)
        patch = limb.mean(axis=(2, 3)).astype(np.float32)
        patch = cv2.GaussianBlur(patch, (0, 0), CORE_SIGMA * sc, borderType=cv2.BORDER_CONSTANT)
        # paste
        H, W = self.H, self.W
        a0, b0 = max(u0, 0), max(v0, 0)
        a1, b1 = min(u1 + 1, W), min(v1 + 1, H)
        if a1 > a0 and b1 > b0:
            sub = patch[b0 - v0 : b1 - v0, a0 - u0 : a1 - u0]
            circ = self.circle[b0:b1, a0:a1]
            q[b0:b1, a0:a1, :] += (sub * circ)[..., None] * (Ldisk * X)[None, None, :]
        # veiling glare wing
        d = np.hypot(self.uu - uv[0], self.vv - uv[1])
        wing = self._wing(d)
        q += (wing * self.circle)[..., None] * (Ldisk * X)[None, None, :]

    def _wing(self, d):
        sc = self.s
        return GLARE_A1 * np.exp(-d / (GLARE_S1 * sc)) + GLARE_A2 * np.exp(-d / (GLARE_S2 * sc))

    def _add_distractors(self, q, t, s, el_s, T):
        sc = self.s
        # (a) specular reflection on a structure
        az0, el0 = 128.0, 3.0
        daz = ((self.az - az0 + 180) % 360 - 180) * math.cos(math.radians(el0))
        de = self.el - el0
        rr = (daz / 0.25) ** 2 + (de / 0.35) ** 2
        blob = np.exp(-0.5 * np.maximum(rr - 0.6, 0) * 8) * (rr < 4)
        q += (40 * FW * blob * self.circle)[..., None] * np.array([0.95, 1.0, 1.0])
        # (b) aircraft glint
        period, dur = 1200.0, 300.0
        k = math.floor(t / period)
        ph = t - k * period
        if ph < dur:
            r = np.random.default_rng([4242, self.seed, int(k) & 0x7FFFFFFF])
            p0 = enu_of(r.uniform(0, 360), r.uniform(15, 40))
            axis = np.cross(p0, enu_of(r.uniform(0, 360), r.uniform(20, 80)))
            axis /= np.linalg.norm(axis)
            p = rotation_about(axis, math.radians(0.5 * ph)) @ p0
            if p[2] > 0.05:
                uv = self.project(p)
                dd = np.hypot(self.uu - uv[0], self.vv - uv[1])
                dot = np.clip(1.25 * sc + 0.5 - dd, 0, 1)
                q += (8 * FW * dot * self.circle)[..., None]
        # (c) lens ghost
        if el_s > 0 and T > 0:
            uv = self.project(s)
            g = np.array([2 * self.cx - uv[0], 2 * self.cy - uv[1]])
            rad = self.f * math.radians(1.0)
            dd = np.hypot(self.uu - g[0], self.vv - g[1])
            prof = np.clip((rad - dd) / (0.35 * rad) + 0.5, 0, 1)
            q += (0.75 * FW * T * prof * self.circle)[..., None] * np.array([0.5, 1.0, 0.55])  # RGB

    def _sensor(self, q, t):
        rng = np.random.default_rng([self.seed, 99, int(round(t * 1000)) & 0x7FFFFFFFFFFF])
        q = np.maximum(q, 0)
        # photon noise: exact Poisson below 1e4 e-, Gaussian approximation above
        lo = q < 1e4
        qn = np.where(lo, 0.0, q + np.sqrt(q) * rng.standard_normal(q.shape))
        qn[lo] = rng.poisson(q[lo])
        # blooming + smear (per channel & column)
        over = qn > FW
        if over.any():
            cols = np.unique(np.nonzero(over)[1])
            for ch in range(3):
                for c in cols:
                    col = qn[:, c, ch]
                    ov = col > FW
                    if not ov.any():
                        continue
                    excess_total = float(np.sum(col[ov] - FW))
                    idx = np.flatnonzero(ov)
                    br = np.flatnonzero(np.diff(idx) > 1)
                    starts = np.r_[idx[0], idx[br + 1]]
                    ends = np.r_[idx[br], idx[-1]] + 1
                    for a, b in zip(starts, ends):
                        E = self.look.bloom * float(np.sum(col[a:b] - FW))
                        col[a:b] = FW
                        half = 0.5 * E
                        # up
                        if a > 0:
                            seg = col[:a][::-1]
                            cap = np.maximum(FW - seg, 0)
                            cs = np.cumsum(cap)
                            add = np.minimum(cap, np.maximum(half - (cs - cap), 0))
                            col[:a] = (seg + add)[::-1]
                        if b < col.size:
                            seg = col[b:]
                            cap = np.maximum(FW - seg, 0)
                            cs = np.cumsum(cap)
                            add = np.minimum(cap, np.maximum(half - (cs - cap), 0))
                            col[b:] = seg + add
                    col += SMEAR * excess_total
                    qn[:, c, ch] = col
        qn = np.minimum(qn, FW)
        qn += READ_E * rng.standard_normal(qn.shape)
        dn = np.clip(np.rint(qn * (1023.0 / FW)), 0, 1023)
        if self.look.tone == "srgb":
            out = np.rint(255 * srgb_encode(dn / 1023.0))
        else:
            out = np.floor(dn / 4)
        img = np.clip(out, 0, 255).astype(np.uint8)[..., ::-1].copy()  # RGB -> BGR
        if self.look.jpeg_quality:
            ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), int(self.look.jpeg_quality)])
            img = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        return img
