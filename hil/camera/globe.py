"""The glossy globe: where camera rays meet it, and its radiance (Lambertian black paint +
GGX microfacet lobe for the sun, Fresnel-weighted mirror of sky and ground).  Radiances in
W m-2 sr-1; vectors in the model frame."""

from __future__ import annotations

import numpy as np

from ..errors import HilError
from .camera import Pose
from .scene import Globe, Scenario

SUN_RADIUS_RAD = np.radians(0.53 / 2)
GROUND_ALBEDO = 0.20


def globe_bbox(scn: Scenario, pose: Pose):
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


def intersect_globe(globe: Globe, C: np.ndarray, d: np.ndarray):
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


def shade_globe(globe: Globe, C, d, s, dni, dhi, n_sun):
    t, u, rho, grad, hit = intersect_globe(globe, C, d)
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
    E = (
        dni * np.clip(n @ s, 0.0, None)
        + dhi * (1 + nz) / 2
        + GROUND_ALBEDO * (dhi + dni * max(s[2], 0.0)) * (1 - nz) / 2
    )
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
            Lout[lobe] += ggx_sun(globe, n[lobe], v[lobe], ndv[lobe], s, dni, n_sun)
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


def ggx_sun(globe: Globe, n, v, ndv, s, dni, n_sun):
    a2 = globe.roughness**2
    out = np.zeros(n.shape[0])
    g1v = 2 * ndv / (ndv + np.sqrt(a2 + (1 - a2) * ndv * ndv))
    for sd in sun_disk_samples(s, n_sun):
        ndl = n @ sd
        ok = ndl > 0
        h = v + sd
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ndh = np.sum(n * h, axis=1)
        D = a2 / (np.pi * (ndh * ndh * (a2 - 1) + 1) ** 2)
        vdh = np.clip(np.sum(v * h, axis=1), 0, 1)
        F = globe.f0 + (1 - globe.f0) * (1 - vdh) ** 5
        ndl_c = np.clip(ndl, 1e-6, 1)
        g1l = 2 * ndl_c / (ndl_c + np.sqrt(a2 + (1 - a2) * ndl_c * ndl_c))
        # radiance = E_sample * f_s * (n.sd),  f_s = D F G / (4 (n.sd)(n.v))
        out += np.where(ok, (dni / n_sun) * D * F * g1v * g1l / (4 * ndv), 0.0)
    return out
