"""Compose a sky-camera frame: sky, clouds, the sun's glare, distractors, smear, sensor.

Signals are linear, per channel, in units of the sensor's full scale (1.0 = grey 255) at
the nominal exposure.  The sensor adds shot and read noise, clips to 8 bits (saturation)
and optionally JPEG-encodes.  Output images are BGR (OpenCV's order), uint8.

Truth per frame (``SkyFrame.truth``): the sun's pvlib azimuth / apparent elevation, its ENU
and camera-frame unit vectors, its pixel, the cloud optical depth on its line of sight and
the beam transmittance, the visibility class used by the benchmark (``visible``: beam
transmittance >= 0.9, a clear line of sight; ``hidden``: the sun's saturated glare, if any,
is under 0.5 deg in radius (not discernible as a sun), or the sun is below the terrain;
``dimmed``: in between, a disk seen through cloud), and
where each distractor is.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from ..errors import HilError
from .clouds import cloud_radiance, optical_depth
from .distractors import AircraftGlint, FlareGhost, SpecularReflection, glint_signal, soft_disk
from .lens import FisheyeLens
from .scene import SkyScene, sun_position
from .sky import SkyModel, ground_and_horizon, sky_radiance, terrain_elevation_deg
from .sun import air_mass_dimming, apply_smear, glare_signal

VISIBLE_T = 0.9
HIDDEN_RADIUS_DEG = 0.5


@dataclass
class SkyFrame:
    image: np.ndarray  # (H, W, 3) uint8, BGR
    truth: dict


@lru_cache(maxsize=6)
def _static(lens: FisheyeLens, enu_from_camera: tuple, sky: SkyModel) -> tuple[np.ndarray, ...]:
    """Per installation: ENU rays of the pixels inside the image circle (N, 3), their flat
    indices, theta (N,), pixel x and y, ``is_sky`` and the ground's radiance."""
    d, ok = lens.rays()
    idx = np.flatnonzero(ok.ravel())
    dc = d.reshape(-1, 3)[idx]
    R = np.asarray(enu_from_camera, np.float32)
    de = np.ascontiguousarray(dc @ R.T)
    theta = np.arccos(np.clip(dc[:, 2], -1.0, 1.0)).astype(np.float32)
    px = (idx % lens.width).astype(np.float32)
    py = (idx // lens.width).astype(np.float32)
    is_sky, ground = ground_and_horizon(sky, de)
    out = (de, idx, theta, px, py, is_sky, ground)
    for a in out:
        a.setflags(write=False)
    return out


def visibility_class(transmittance: float, glare_radius_deg: float, above_terrain: bool) -> str:
    """``visible``, ``dimmed`` or ``hidden`` (see the module's docstring)."""
    if not above_terrain or glare_radius_deg < HIDDEN_RADIUS_DEG:
        return "hidden"
    return "visible" if transmittance >= VISIBLE_T else "dimmed"


def render_sky(
    scn: SkyScene,
    t: float,
    *,
    rng: np.random.Generator | None = None,
    sun: tuple[float, float] | None = None,
    sun_transmittance: float | None = None,
    exposure: float | None = None,
) -> SkyFrame:
    """Render the sky camera's frame at POSIX time ``t``.

    ``sun``: (azimuth, apparent elevation) in deg to skip the SPA call (must be the truth at
    ``t``); ``sun_transmittance``: override the clouds' beam transmittance for the sun
    (e.g. to follow another cloud model); ``exposure``: override the sensor's.
    """
    if sun_transmittance is not None and not 0.0 <= sun_transmittance <= 1.0:
        raise HilError(f"sun transmittance must be within 0..1, got {sun_transmittance}")
    rng = rng if rng is not None else np.random.default_rng(int(t * 1000) & 0xFFFFFFFF)
    lens = scn.lens
    H, W = lens.height, lens.width
    R = scn.R_enu_from_cam
    if sun is None:
        sp = sun_position(scn.site, [t])
        az, el = float(sp["azimuth"][0]), float(sp["elevation"][0])
    else:
        az, el = float(sun[0]), float(sun[1])
    a, e = np.radians(az), np.radians(el)
    s_enu = np.array([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)])
    s_cam = R.T @ s_enu
    de, idx, theta, px, py, is_sky, ground = _static(lens, scn.enu_from_camera, scn.sky)
    L = sky_radiance(scn.sky, de, s_enu, el, is_sky, ground)
    cos_chi = np.clip(de @ s_enu.astype(np.float32), -1.0, 1.0)
    chi = np.arccos(cos_chi)
    chi_deg = np.degrees(chi)

    terrain = float(terrain_elevation_deg(scn.sky, np.array([a]))[0])
    above = el > terrain
    dim = air_mass_dimming(el) if above else 0.0
    tau = np.zeros(de.shape[0], np.float32)
    tau_sun = 0.0
    if scn.clouds is not None:
        sky_idx = np.flatnonzero(is_sky)
        tau[sky_idx] = optical_depth(scn.clouds, de[sky_idx], t, 1.0 / lens.fx)
        tau_sun = float(optical_depth(scn.clouds, s_enu[None, :], t)[0])
    T_sun = float(np.exp(-tau_sun)) if sun_transmittance is None else float(sun_transmittance)
    T_sun = T_sun if above else 0.0
    if scn.clouds is not None:
        cl = np.flatnonzero(tau > 1e-4)
        L[cl] = cloud_radiance(
            scn.clouds, tau[cl], L[cl], chi[cl], dim * min(1.0, T_sun + 0.3), scn.sky.zenith_level
        )

    if scn.sensor.auto_exposure:
        away = L[::7][chi[::7] > np.radians(20.0)]  # the metering ignores the sun's surroundings
        grey = away @ np.array([0.299, 0.587, 0.114], np.float32)
        p97 = float(np.percentile(grey, 97)) if grey.size else 1.0
        auto = float(np.clip(scn.sensor.auto_target / max(p97, 1e-6), 0.25, 4.0))
    else:
        auto = 1.0
    sig = L * auto
    uv_sun, in_circle = lens.project(s_cam[None, :])
    uv_sun = uv_sun[0]
    f_deg = float(np.degrees(1.0 / (0.5 * (lens.fx + lens.fy))))  # deg per px at the centre
    exposure = (scn.sensor.exposure if exposure is None else exposure) * auto
    g = scn.glare
    strength = exposure * T_sun * dim * g.amplitude
    glare = None
    if strength > 0:
        pix_deg = np.hypot(px - uv_sun[0], py - uv_sun[1]) * f_deg
        aur_T = 0.8 + 0.2 * np.exp(-tau)  # the aureole is mostly scattered below the clouds
        glare = glare_signal(g, chi_deg, pix_deg, strength, aur_T)
        warm = np.asarray(g.warm, np.float32)
        mix = float(np.clip(el / 20.0, 0.0, 1.0))
        colour = mix * np.ones(3, np.float32) + (1.0 - mix) * warm
        sig = sig + glare[:, None] * colour[None, :]

    truth_d = []
    for dis in scn.distractors:
        rec = {"kind": dis.kind}
        if isinstance(dis, SpecularReflection):
            d_enu = dis.direction_enu(t)
            lit = dim if not dis.follows_sun else dim * T_sun
            st = exposure * lit * g.amplitude * dis.strength
            dchi = np.degrees(np.arccos(np.clip(de @ d_enu.astype(np.float32), -1, 1)))
            duv = lens.project((R.T @ d_enu)[None, :])[0][0]
            pdeg = np.hypot(px - duv[0], py - duv[1]) * f_deg
            if st > 0:
                sig = sig + glare_signal(g, dchi, pdeg, st)[:, None]
            rec.update(enu=d_enu.tolist(), uv=duv.tolist(), lit=bool(st > 0))
        elif isinstance(dis, AircraftGlint):
            g_enu = dis.direction_enu(t)
            if g_enu is None or el <= 0:
                continue
            d_enu = g_enu
            duv = lens.project((R.T @ d_enu)[None, :])[0][0]
            dist = np.hypot(px - duv[0], py - duv[1])
            sig = sig + glint_signal(dist, dis.radius_px)[:, None] * exposure
            rec.update(enu=d_enu.tolist(), uv=duv.tolist())
        elif isinstance(dis, FlareGhost):
            if strength <= 0 or not in_circle[0]:
                continue
            c = np.array([lens.cx, lens.cy])
            guv = c - dis.position * (uv_sun - c)
            dist = np.hypot(px - guv[0], py - guv[1])
            amp = dis.level * exposure * T_sun * dim
            sig = sig + (amp * soft_disk(dist, dis.radius_px, 2.5))[:, None] * np.asarray(
                dis.tint, np.float32
            )
            rec.update(uv=guv.tolist())
        truth_d.append(rec)

    flat = np.zeros((H * W, 3), np.float32)
    vig = 1.0 - scn.sensor.vignetting * (theta / lens.theta_max) ** 2
    flat[idx] = sig * vig[:, None]
    img = flat.reshape(H, W, 3)
    if glare is not None and g.smear != "none":
        full_flat = np.zeros(H * W, np.float32)
        full_flat[idx] = glare * vig
        full = full_flat.reshape(H, W)
        rr, cc = np.nonzero(full >= 0.02)
        if rr.size:
            roi = (int(rr.min()), int(rr.max()) + 1, int(cc.min()), int(cc.max()) + 1)
            apply_smear(g, img, full[roi[0] : roi[1], roi[2] : roi[3]], roi)
    image = expose(img, scn, rng)
    sat_r = (g.core_deg * np.sqrt(max(strength, 1.0) ** (2.0 / g.power) - 1.0)) if strength > 1 else 0.0
    truth = {
        "time": float(t),
        "az_deg": az,
        "el_deg": el,
        "sun_enu": s_enu,
        "sun_cam": s_cam,
        "sun_uv": uv_sun.tolist(),
        "sun_in_image": bool(in_circle[0]),
        "terrain_deg": terrain,
        "tau_sun": tau_sun,
        "transmittance": T_sun,
        "air_mass_dimming": dim,
        "glare_radius_deg": float(sat_r),
        "exposure": exposure,
        "visibility": visibility_class(T_sun, float(sat_r), above and bool(in_circle[0])),
        "cloud_fraction": float(np.mean(tau[is_sky] > 0.1)) if scn.clouds is not None else 0.0,
        "distractors": truth_d,
        "enu_from_camera": R,
    }
    return SkyFrame(image, truth)


def expose(signal: np.ndarray, scn: SkyScene, rng: np.random.Generator) -> np.ndarray:
    """Linear signal (H, W, 3 RGB, full scale = 1) -> noisy 8-bit BGR, optionally via JPEG."""
    sen = scn.sensor
    x = signal
    if sen.noise:
        e = np.minimum(x, 4.0) * sen.full_well_e
        e = e + rng.standard_normal(e.shape, dtype=np.float32) * np.sqrt(
            np.maximum(e, 0.0) + sen.read_noise_e**2
        )
        x = e / sen.full_well_e
    dn = np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8)[:, :, ::-1]
    dn = np.ascontiguousarray(dn)
    if sen.noise and sen.jpeg_quality:
        _ok, buf = cv2.imencode(".jpg", dn, [cv2.IMWRITE_JPEG_QUALITY, int(sen.jpeg_quality)])
        return np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), np.uint8)
    return dn
