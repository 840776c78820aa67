"""Physically plausible renderer for the hotspot sensor and its calibration views.

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
from .camera import CameraModel, Pose
from .scene import Base, Globe, Scenario

SUN_RADIUS_RAD = np.radians(0.53 / 2)
GROUND_ALBEDO = 0.20


@dataclass
class Frame:
    image: np.ndarray  # uint8 (H, W)
    truth: dict


# ----------------------------------------------------------------------------------------
def render_frame(scn: Scenario, t: float, *, transmittance: float = 1.0,
                 rng: np.random.Generator | None = None, pose: Pose | None = None,
                 exposure_factor: float = 1.0) -> Frame:
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
    dhi = float(sun["dhi"][0]) + 0.25 * float(sun["dni"][0]) * (1 - transmittance) \
        * max(np.sin(np.radians(sun["elevation"][0])), 0.0)
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


def expose(L: np.ndarray, scn: Scenario, rng: np.random.Generator,
           exposure_factor: float = 1.0) -> np.ndarray:
    """Radiance -> 8-bit grey: shot + read noise, quantisation, saturation, optional JPEG."""
    sen = scn.sensor
    frac = L * (exposure_factor / sen.full_scale_radiance)
    if sen.noise:
        e = frac * sen.full_well_e
        e = np.minimum(e, 4.0 * sen.full_well_e)  # well overflow: irrelevant beyond clip
        e = e + rng.standard_normal(e.shape, dtype=np.float32) * np.sqrt(
            np.maximum(e, 0.0) + sen.read_noise_e ** 2)
        frac = e / sen.full_well_e
    dn = np.clip(np.rint(frac * 255.0), 0, 255).astype(np.uint8)
    if sen.noise and sen.jpeg_quality:
        ok, buf = cv2.imencode(".jpg", dn, [cv2.IMWRITE_JPEG_QUALITY, int(sen.jpeg_quality)])
        dn = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return dn


# ----------------------------------------------------------------------------------------
def radiance_image(scn: Scenario, pose: Pose, s_model: np.ndarray, dni: float,
                   dhi: float) -> np.ndarray:
    cam = scn.camera
    H, W = cam.height, cam.width
    dcam = cam.ray_dirs()
    R = np.asarray(pose.R, float)
    C = pose.center
    dw = (dcam.reshape(-1, 3) @ R).astype(np.float32)  # d_world = R^T d_cam
    L = _background(scn, C, dw, s_model, dni, dhi, pose).reshape(H, W)
    box = _globe_bbox(scn, pose)
    if box is not None:
        r0, r1, c0, c1 = box
        d = dcam[r0:r1, c0:c1].reshape(-1, 3) @ R
        Lg, hit = _shade_globe(scn.globe, C, d, s_model, dni, dhi, scn.sun_samples)
        sub = L[r0:r1, c0:c1].reshape(-1)
        sub[hit] = Lg[hit]
        L[r0:r1, c0:c1] = sub.reshape(r1 - r0, c1 - c0)
    return L


def _globe_bbox(scn: Scenario, pose: Pose):
    cam = scn.camera
    C = pose.center
    Rg = scn.globe.radius + 3 * max(scn.globe.bump_amplitude_m, 0.0) + 1e-3
    D = np.linalg.norm(C)
    if D <= Rg:
        raise HilError("camera inside the globe")
    a = -C / D
    e1 = np.cross(a, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(a, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    ang = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    cc = C + a * (D - Rg * Rg / D)
    rr = Rg * np.sqrt(1 - (Rg / D) ** 2)
    pts = cc + rr * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    pts = pts[pts[:, 2] >= -0.01]
    pts = np.vstack([pts, [[0, 0, Rg]]])
    pc = pts @ np.asarray(pose.R).T + pose.tvec
    if np.any(pc[:, 2] <= 0):
        return (0, cam.height, 0, cam.width)
    uv = cam.project(pts, pose.rvec, pose.tvec)
    c0 = int(np.floor(uv[:, 0].min())) - 4
    c1 = int(np.ceil(uv[:, 0].max())) + 5
    r0 = int(np.floor(uv[:, 1].min())) - 4
    r1 = int(np.ceil(uv[:, 1].max())) + 5
    c0, r0 = max(c0, 0), max(r0, 0)
    c1, r1 = min(c1, cam.width), min(r1, cam.height)
    if c1 <= c0 or r1 <= r0:
        return None
    return (r0, r1, c0, c1)


def _intersect_globe(globe: Globe, C: np.ndarray, d: np.ndarray):
    """Ray (origin C, unit dirs d (N,3)) vs the (bumpy) hemisphere; returns t, u, rho, grad, hit."""
    b = d @ C
    c0 = C @ C
    rho = np.full(d.shape[0], globe.radius)
    t = np.full(d.shape[0], np.nan)
    for _ in range(4 if globe.bump_amplitude_m else 1):
        disc = b * b - (c0 - rho * rho)
        with np.errstate(invalid="ignore"):
            t = -b - np.sqrt(disc)
        p = C + t[:, None] * d
        nrm = np.linalg.norm(p, axis=1)
        u = p / nrm[:, None]
        h, grad = globe.height(np.nan_to_num(u))
        rho = globe.radius + h
    hit = np.isfinite(t) & (t > 0) & (p[:, 2] >= 0)
    return t, u, rho, grad, hit


def _shade_globe(globe: Globe, C, d, s, dni, dhi, n_sun):
    t, u, rho, grad, hit = _intersect_globe(globe, C, d)
    L = np.zeros(d.shape[0])
    if not hit.any():
        return L, hit
    idx = np.nonzero(hit)[0]
    n = Globe.normal(u[idx], rho[idx], grad[idx])
    v = -d[idx]
    ndv = np.clip(np.sum(n * v, axis=1), 1e-4, 1.0)
    nz = n[:, 2]
    s = np.asarray(s, float)
    # diffuse: direct + sky + ground
    E = dni * np.clip(n @ s, 0.0, None) + dhi * (1 + nz) / 2 \
        + GROUND_ALBEDO * (dhi + dni * max(s[2], 0.0)) * (1 - nz) / 2
    Lout = globe.albedo / np.pi * E
    # specular mirror of the environment (sky above, ground below)
    r = 2 * ndv[:, None] * n - v
    F_v = globe.f0 + (1 - globe.f0) * (1 - ndv) ** 5
    L_sky = dhi / np.pi
    L_ground = GROUND_ALBEDO / np.pi * (dhi + dni * max(s[2], 0.0))
    Lout += F_v * np.where(r[:, 2] > 0, L_sky, L_ground)
    # specular sun lobe, only where the normal is within the lobe
    if dni > 0 and s[2] > -0.01:
        h0 = v + s
        h0 /= np.linalg.norm(h0, axis=1, keepdims=True)
        lobe = np.sum(n * h0, axis=1) > np.cos(np.radians(25.0) + 8 * globe.roughness)
        if lobe.any():
            Lout[lobe] += _ggx_sun(globe, n[lobe], v[lobe], ndv[lobe], s, dni, n_sun)
    L[idx] = Lout
    return L, hit


def sun_disk_samples(s: np.ndarray, n: int) -> np.ndarray:
    """``n`` unit directions spread uniformly (equal area) over the sun's 0.53 deg disk."""
    s = np.asarray(s, float) / np.linalg.norm(s)
    if n <= 1:
        return s[None, :]
    e1 = np.cross(s, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(s, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(s, e1)
    k = np.arange(n) + 0.5
    rad = SUN_RADIUS_RAD * np.sqrt(k / n)  # Fibonacci / sunflower disk
    ang = k * np.pi * (3 - np.sqrt(5))
    out = s + rad[:, None] * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _ggx_sun(globe: Globe, n, v, ndv, s, dni, n_sun):
    a2 = globe.roughness ** 2
    out = np.zeros(n.shape[0])
    g1v = 2 * ndv / (ndv + np.sqrt(a2 + (1 - a2) * ndv * ndv))
    for l in sun_disk_samples(s, n_sun):
        ndl = n @ l
        ok = ndl > 0
        h = v + l
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ndh = np.sum(n * h, axis=1)
        D = a2 / (np.pi * (ndh * ndh * (a2 - 1) + 1) ** 2)
        vdh = np.clip(np.sum(v * h, axis=1), 0, 1)
        F = globe.f0 + (1 - globe.f0) * (1 - vdh) ** 5
        ndl_c = np.clip(ndl, 1e-6, 1)
        g1l = 2 * ndl_c / (ndl_c + np.sqrt(a2 + (1 - a2) * ndl_c * ndl_c))
        # radiance = E_sample * f_s * (n.l),  f_s = D F G / (4 (n.l)(n.v))
        out += np.where(ok, (dni / n_sun) * D * F * g1v * g1l / (4 * ndv), 0.0)
    return out


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
    shadow = (bproj < 0) & (bproj * bproj > px * px + py * py - scn.globe.radius ** 2)
    E = np.where(shadow, 0.0, dni * sz) + dhi
    footprint = np.linalg.norm(C) / np.sqrt(cam.fx * cam.fy)
    tex = _base_texture(base, 0.5 * footprint / base.texture_res)
    mapx = ((x + base.half_size) / base.texture_res - 0.5).astype(np.float32)
    mapy = ((base.half_size - y) / base.texture_res - 0.5).astype(np.float32)
    mapx[~down] = -10
    H, W = cam.height, cam.width
    alb = cv2.remap(tex, mapx.reshape(H, W), mapy.reshape(H, W), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0).reshape(-1)
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
def render_checkerboard(cam: CameraModel, rvec, tvec, *, pattern=(9, 6), square=0.04,
                        rng: np.random.Generator | None = None, noise_dn: float = 1.5) -> np.ndarray:
    """A planar checkerboard (``pattern`` inner corners, ``square`` m) at pose board->camera.

    Board frame: x along the columns, y along the rows, z into the board; inner corner
    (i, j) sits at ((i+1) square, (j+1) square, 0).  Edges are box-filtered analytically
    per pixel so the corners are sub-pixel exact.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    Rb = cv2.Rodrigues(np.asarray(rvec, float))[0]
    tb = np.asarray(tvec, float).ravel()
    d = cam.ray_dirs()
    nb = Rb[:, 2]
    denom = d @ nb
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (nb @ tb) / denom
    P = d * tt[..., None] - tb
    X = P @ Rb  # board coords = R^T (p - t)
    a = X[..., 0] / square
    b = X[..., 1] / square
    valid = np.isfinite(tt) & (tt > 0)
    a = np.where(valid, a, -100)
    b = np.where(valid, b, -100)
    wa = np.abs(np.gradient(a, axis=1)) + np.abs(np.gradient(a, axis=0)) + 1e-9
    wb = np.abs(np.gradient(b, axis=1)) + np.abs(np.gradient(b, axis=0)) + 1e-9

    def smooth_sign(x, w):
        f = x - np.floor(x)
        dist = np.minimum(f, 1 - f)  # to nearest integer edge
        sgn = np.where(np.floor(x) % 2 == 0, 1.0, -1.0)
        return sgn * np.clip(2 * dist / w, 0, 1)

    val = 0.5 + 0.5 * smooth_sign(a, wa) * smooth_sign(b, wb)
    nx, ny = pattern
    inside = (a > 0) & (a < nx + 1) & (b > 0) & (b < ny + 1)
    margin = (a > -1) & (a < nx + 2) & (b > -1) & (b < ny + 2)
    img = np.full(a.shape, 0.35)
    img = np.where(margin & valid, 0.92, img)
    img = np.where(inside & valid, 0.08 + 0.84 * val, img)
    dn = img * 230 + rng.normal(0, noise_dn, img.shape)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def checkerboard_poses(cam: CameraModel, n: int, rng: np.random.Generator, *, pattern=(9, 6),
                       square=0.04) -> list[tuple[np.ndarray, np.ndarray]]:
    """Varied board poses that keep the whole board in view (for intrinsics)."""
    nx, ny = pattern
    w, h = (nx + 1) * square, (ny + 1) * square
    poses = []
    tries = 0
    while len(poses) < n and tries < 50 * n:
        tries += 1
        # distance so that the board covers ~40-70 % of the smaller image side
        frac = rng.uniform(0.45, 0.8)
        dist = max(cam.fx, cam.fy) * max(w, h) / (frac * min(cam.width, cam.height) * 1.2)
        ang = np.radians(rng.uniform(-35, 35, 3)) * np.array([1, 1, 0.5])
        Rb = cv2.Rodrigues(ang)[0]
        # aim the board centre at a random image point
        u = rng.uniform(0.2, 0.8) * cam.width
        v = rng.uniform(0.2, 0.8) * cam.height
        ray = cam.rays_at([[u, v]])[0]
        centre = ray * dist / ray[2]
        tb = centre - Rb @ np.array([w / 2, h / 2, 0.0])
        corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
        pc = corners @ Rb.T + tb
        if np.any(pc[:, 2] < 0.05):
            continue
        uv = cam.project(corners, cv2.Rodrigues(Rb)[0], tb)
        if (uv.min() < 10 or np.any(uv[:, 0] > cam.width - 10) or np.any(uv[:, 1] > cam.height - 10)):
            continue
        poses.append((cv2.Rodrigues(Rb)[0].ravel(), tb))
    return poses


def plumb_lines(scn: Scenario, n_lines: int = 4) -> list[tuple[np.ndarray, np.ndarray]]:
    """Plumb strings (model frame): (top point, bottom point), hung between camera and globe,
    beside the globe, truly vertical (along the ENU zenith)."""
    cam = scn.camera
    pose = scn.pose
    zen = scn.zenith_model
    C = pose.center
    D = np.linalg.norm(C)
    out = []
    r0, r1, c0, c1 = _globe_bbox(scn, pose)
    W = cam.width
    k = max(n_lines // 2, 1)
    left = np.linspace(0.08 * W, max(c0 - 0.05 * W, 0.1 * W), k)
    right = np.linspace(min(c1 + 0.05 * W, 0.9 * W), 0.92 * W, n_lines - k)
    xs = np.concatenate([left, right]) / W
    vrow = min(0.5 * (r0 + r1) / cam.height + 0.1, 0.8)
    for fx_ in xs:
        ray_cam = cam.rays_at([[fx_ * cam.width, vrow * cam.height]])[0]
        ray = np.asarray(pose.R).T @ ray_cam
        P = C + ray * 0.75 * D
        top = P + zen * 0.35
        bot = P - zen * 0.35
        if bot @ zen < 0.005:  # keep above the base
            bot = P - zen * ((P @ zen) - 0.005)
        out.append((top, bot))
    return out


def render_plumb_view(scn: Scenario, t: float, *, n_lines: int = 4, string_diameter=0.003,
                      rng: np.random.Generator | None = None) -> Frame:
    """The installed camera's view with plumb strings hung in it (for levelling)."""
    rng = rng if rng is not None else np.random.default_rng(1)
    pose = scn.pose
    sun = scn.sun([t])
    s_model = sun["model"][0]
    L = radiance_image(scn, pose, s_model, float(sun["dni"][0]), float(sun["dhi"][0]))
    cam = scn.camera
    d = cam.ray_dirs().reshape(-1, 3) @ np.asarray(pose.R)
    C = pose.center
    f = np.sqrt(cam.fx * cam.fy)
    lines = plumb_lines(scn, n_lines)
    Lf = L.reshape(-1)
    L_string = 0.04 / np.pi * (float(sun["dhi"][0]) + 0.3 * float(sun["dni"][0]))
    truth_lines = []
    for top, bot in lines:
        z = (top - bot) / np.linalg.norm(top - bot)
        w = C - bot
        # closest points between ray C + t d and line bot + s z
        dz = d @ z
        denom = 1 - dz ** 2
        dw = d @ w
        zw = z @ w
        tr = (dz * zw - dw) / np.maximum(denom, 1e-12)
        sl = (zw - dz * dw) / np.maximum(denom, 1e-12)
        seg = np.linalg.norm(top - bot)
        cl = C + tr[:, None] * d - (bot + np.clip(sl, 0, seg)[:, None] * z)
        dist_px = np.linalg.norm(cl, axis=1) / np.maximum(tr, 1e-6) * f
        rad_px = string_diameter / 2 / np.maximum(tr, 1e-6) * f
        cov = np.clip(rad_px - dist_px + 0.5, 0, 1) * (tr > 0)
        Lf = Lf * (1 - cov) + L_string * cov
        samples = bot + np.linspace(0, seg, 50)[:, None] * z
        truth_lines.append(cam.project(samples, pose.rvec, pose.tvec))
    img = expose(Lf.reshape(L.shape).astype(np.float32), scn, rng, exposure_factor=2.0)
    return Frame(img, {"lines_uv": truth_lines, "zenith_model": scn.zenith_model,
                       "lines_model": lines})


def render_marker_view(scn: Scenario, t: float, rng: np.random.Generator | None = None) -> Frame:
    """The installed camera's view used for exterior orientation (longer exposure)."""
    return render_frame(scn, t, rng=rng, pose=scn.pose, exposure_factor=2.0)
