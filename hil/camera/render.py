"""Physically plausible renderer for the hotspot sensor (calibration views: :mod:`.views`).

Radiometry (all radiances in W m-2 sr-1):

* sun: a 0.53 deg disk sampled by ``Scenario.sun_samples`` directions, each carrying an equal
  share of the direct-normal irradiance (clear sky: Meinel air-mass model; times the cloud
  transmittance of the frame);
* sky: isotropic radiance DHI/pi (the cloud's share of the direct beam is added to it);
* globe: Lambertian black paint (albedo 0.04) + GGX microfacet specular lobe (Smith G,
  Schlick Fresnel, F0 = 0.04) for the sun, and a Fresnel-weighted mirror of sky/ground;
* base/ground: Lambertian, with the globe's hard shadow; markers printed on the base.

The sensor converts radiance to electrons (``full_well_e`` at ``full_scale_radiance``), adds
shot and read noise, quantises to 8 bits with saturation and optionally JPEG-encodes.
Only the globe's projected bounding box is ray-cast against the sphere, and only the pixels
whose normal lies within the specular lobe get the (per-sun-sample) microfacet evaluation.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from ..errors import HilError
from .camera import Pose
from .globe import GROUND_ALBEDO, globe_bbox, shade_globe
from .scene import Base, Scenario


@dataclass
class Frame:
    image: np.ndarray  # uint8 (H, W)
    truth: dict


# ----------------------------------------------------------------------------------------
def render_frame(
    scn: Scenario,
    t: float,
    *,
    transmittance: float = 1.0,
    rng: np.random.Generator | None = None,
    pose: Pose | None = None,
    exposure_factor: float = 1.0,
) -> Frame:
    """Render the sensor's frame at POSIX time ``t`` for scenario ``scn``.

    ``transmittance`` (0..1) scales the direct beam (clouds); ``pose`` overrides the nominal
    camera pose (else the nominal pose with the scenario's jitter); ``exposure_factor`` > 1
    lengthens the exposure.  Returns the 8-bit image and the truth (sun az/el/ENU/model,
    pose, glint pixel of the ideal sphere).
    """
    if not 0.0 <= transmittance <= 1.0:
        raise HilError(f"cloud transmittance must be within 0..1, got {transmittance}")
    rng = rng if rng is not None else np.random.default_rng(int(t) & 0xFFFFFFFF)
    sun = scn.sun([t])
    s_model = sun["model"][0]
    dni = float(sun["dni"][0]) * transmittance
    dhi = float(sun["dhi"][0]) + 0.25 * float(sun["dni"][0]) * (1 - transmittance) * max(
        np.sin(np.radians(sun["elevation"][0])), 0.0
    )
    if pose is None:
        pose = scn.pose.perturbed(rng, scn.pose_jitter_deg, scn.pose_jitter_m)
    L = radiance_image(scn, pose, s_model, dni, dhi)
    img = expose(L, scn, rng, exposure_factor)
    truth = {
        "time": float(t),
        "az_deg": float(sun["azimuth"][0]),
        "el_deg": float(sun["elevation"][0]),
        "sun_enu": sun["enu"][0],
        "sun_model": s_model,
        "dni": dni,
        "rvec": pose.rvec,
        "tvec": pose.tvec,
        "R_model_to_enu": scn.R_model_to_enu,
        "zenith_model": scn.zenith_model,
        "glint_uv": glint_pixel(scn, pose, s_model) if sun["elevation"][0] > 0 else None,
    }
    return Frame(img, truth)


def expose(
    L: np.ndarray, scn: Scenario, rng: np.random.Generator, exposure_factor: float = 1.0
) -> np.ndarray:
    """Radiance -> 8-bit grey: shot + read noise, quantisation, saturation, optional JPEG."""
    sen = scn.sensor
    frac = L * (exposure_factor / sen.full_scale_radiance)
    if sen.noise:
        e = frac * sen.full_well_e
        e = np.minimum(e, 4.0 * sen.full_well_e)  # well overflow: irrelevant beyond clip
        e = e + rng.standard_normal(e.shape, dtype=np.float32) * np.sqrt(
            np.maximum(e, 0.0) + sen.read_noise_e**2
        )
        frac = e / sen.full_well_e
    dn = np.clip(np.rint(frac * 255.0), 0, 255).astype(np.uint8)
    if sen.noise and sen.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", dn, [cv2.IMWRITE_JPEG_QUALITY, int(sen.jpeg_quality)])
        dn = np.asarray(cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE), np.uint8)
    return dn


# ----------------------------------------------------------------------------------------
def radiance_image(scn: Scenario, pose: Pose, s_model: np.ndarray, dni: float, dhi: float) -> np.ndarray:
    cam = scn.camera
    H, W = cam.height, cam.width
    dcam = cam.ray_dirs()
    R = np.asarray(pose.R, float)
    C = pose.center
    dw = (dcam.reshape(-1, 3) @ R).astype(np.float32)  # d_world = R^T d_cam
    L = _background(scn, C, dw, s_model, dni, dhi, pose).reshape(H, W)
    box = globe_bbox(scn, pose)
    if box is not None:
        r0, r1, c0, c1 = box
        d = dcam[r0:r1, c0:c1].reshape(-1, 3) @ R
        Lg, hit = shade_globe(scn.globe, C, d, s_model, dni, dhi, scn.sun_samples)
        sub = L[r0:r1, c0:c1].reshape(-1)
        sub[hit] = Lg[hit]
        L[r0:r1, c0:c1] = sub.reshape(r1 - r0, c1 - c0)
    return L


@lru_cache(maxsize=8)
def _base_texture(base: Base, sigma_texels: float) -> np.ndarray:
    tex = base.texture
    if sigma_texels > 0.3:
        tex = cv2.GaussianBlur(tex, (0, 0), sigma_texels)
    return tex


def _background(scn: Scenario, C, dw, s, dni, dhi, pose: Pose) -> np.ndarray:
    """Radiance of base, ground and sky for all pixels (flat float32 array)."""
    base = scn.base
    cam = scn.camera
    N = dw.shape[0]
    L = np.full(N, dhi / np.pi, np.float32)  # sky
    dz = dw[:, 2]
    down = dz < -1e-6
    tt = np.where(down, -C[2] / np.where(down, dz, -1.0), 0.0).astype(np.float32)
    x = C[0] + tt * dw[:, 0]
    y = C[1] + tt * dw[:, 1]
    # irradiance on the base: direct (unless in the globe's shadow) + sky
    sz = max(float(s[2]), 0.0)
    px = x.astype(np.float64)
    py = y.astype(np.float64)
    bproj = px * s[0] + py * s[1]
    shadow = (bproj < 0) & (bproj * bproj > px * px + py * py - scn.globe.radius**2)
    E = np.where(shadow, 0.0, dni * sz) + dhi
    footprint = np.linalg.norm(C) / np.sqrt(cam.fx * cam.fy)
    tex = _base_texture(base, 0.5 * footprint / base.texture_res)
    mapx = ((x + base.half_size) / base.texture_res - 0.5).astype(np.float32)
    mapy = ((base.half_size - y) / base.texture_res - 0.5).astype(np.float32)
    mapx[~down] = -10
    H, W = cam.height, cam.width
    alb = cv2.remap(
        tex,
        mapx.reshape(H, W),
        mapy.reshape(H, W),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=-1.0,
    ).reshape(-1)
    alb = np.where(alb < 0, GROUND_ALBEDO, alb)
    L = np.where(down, alb / np.pi * E, L).astype(np.float32)
    return L


def glint_pixel(scn: Scenario, pose: Pose, s_model) -> tuple[float, float] | None:
    """Image position of the ideal sphere's mirror point for the sun's centre (truth)."""
    C = pose.center
    R = scn.globe.radius
    s = np.asarray(s_model, float)
    n = s.copy()
    for _ in range(50):
        p = R * n
        v = (C - p) / np.linalg.norm(C - p)
        n_new = (v + s) / np.linalg.norm(v + s)
        if np.linalg.norm(n_new - n) < 1e-13:
            break
        n = n_new
    p = R * n
    v = (C - p) / np.linalg.norm(C - p)
    if p[2] < 0 or n @ v <= 0:
        return None
    uv = scn.camera.project(p[None], pose.rvec, pose.tvec)[0]
    if not (0 <= uv[0] < scn.camera.width and 0 <= uv[1] < scn.camera.height):
        return None
    return float(uv[0]), float(uv[1])


# ----------------------------------------------------------------------------------------
# calibration views
