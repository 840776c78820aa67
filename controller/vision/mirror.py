"""The mirror law on a convex surface, the glint lobe's offset, and levelling rotations.

Unit vectors; ``n`` the outward surface normal, ``v`` the direction from the surface point
TOWARD the camera, ``s`` the direction toward the sun.
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def mirror_sun_direction(n: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mirror law: sun direction s = 2 (v . n) n - v.

    ``n``: unit outward normal(s); ``v``: unit vector(s) from the surface point TOWARD the
    camera.  (The paper's r = point - camera centre would give -s, the direction the light
    travels.)
    """
    n = np.asarray(n, float)
    v = np.asarray(v, float)
    return 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n - v


def incidence_frame(s, vbar):
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
    return incidence_frame(s, vbar)[0]


def lobe_correct(s, vbar, coeff_deg: float) -> np.ndarray:
    """Lobe-offset model: the glint's centroid direction is biased by coeff_deg * tan(theta_i)
    away from the camera, in the plane of incidence (the 1/(n.v) and Fresnel factors tilt the
    microfacet lobe); remove it."""
    t, inc = incidence_frame(s, vbar)
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
