"""Sky and ground radiance of the HIL sky camera (linear, RGB, in units of the sensor's full
scale at the nominal exposure).

The clear sky follows the CIE general sky (ISO 15469) with a gradation between groups IV and III
(a = -1, b = -0.8: the horizon about 1.8 times the zenith) and a milder indicatrix than the clear
types' (c = 0.8, d = -2, e = 0.45), so that the sun's saturated disk is set by the glare
model (:mod:`.sun`), not by the sky:

    L / L_zenith = f(chi) phi(Z) / (f(Z_sun) phi(0))
    phi(Z) = 1 + a exp(b / cos Z)                    (gradation: horizon brightening)
    f(chi) = 1 + c (exp(d chi) - exp(d pi/2)) + e cos^2 chi   (indicatrix: the aureole)

with ``Z`` the zenith angle of the view, ``Z_sun`` that of the sun and ``chi`` the angle
between view and sun.  The colour goes from a saturated blue at the zenith, far from the
sun, to white near the sun and the horizon.  The camera is auto-exposed, so the zenith
level is the same every frame.  Below the terrain horizon is dark, slightly textured ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# CIE gradation group IV; an indicatrix milder than the clear types' (see the docstring)
_A, _B, _C, _D, _E = -1.0, -0.8, 0.8, -2.0, 0.45

BLUE = np.array([0.48, 0.70, 1.0], np.float32)  # R, G, B of the deep sky (normalised)
WHITE = np.array([1.0, 1.0, 1.0], np.float32)
GROUND = np.array([0.55, 0.50, 0.36], np.float32)


@dataclass(frozen=True)
class SkyModel:
    """Clear-sky look.  ``zenith_level``: the dome's mean blue-channel signal for the zenith
    sun (full scale = 1; the sky dims with the sun's elevation like the diffuse irradiance);
    ``terrain_deg``: peak height of the distant terrain above the true horizon (deg);
    ``ground_level``: mean ground signal."""

    zenith_level: float = 0.30
    terrain_deg: float = 0.3
    terrain_seed: int = 3
    ground_level: float = 0.22


def _gradation(cos_z: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", over="ignore"):
        return 1.0 + _A * np.exp(_B / np.maximum(cos_z, 1e-3))


def _indicatrix(chi: np.ndarray) -> np.ndarray:
    return 1.0 + _C * (np.exp(_D * chi) - np.exp(_D * np.pi / 2)) + _E * np.cos(chi) ** 2


_DOME = None


def _dome_mean(sun_enu: np.ndarray) -> float:
    """Mean of indicatrix x gradation over the upper hemisphere (equal-area samples)."""
    global _DOME
    if _DOME is None:
        n = 800
        k = np.arange(n) + 0.5
        z = 1.0 - k / n  # uniform in cos(zenith): equal area
        az = np.pi * (1 + 5**0.5) * k  # golden-angle spiral
        r = np.sqrt(1 - z * z)
        _DOME = np.stack([r * np.cos(az), r * np.sin(az), z], 1).astype(np.float32)
    chi = np.arccos(np.clip(_DOME @ np.asarray(sun_enu, np.float32), -1.0, 1.0))
    return float(np.mean(_indicatrix(chi) * _gradation(_DOME[:, 2])))


def terrain_elevation_deg(model: SkyModel, az_rad: np.ndarray) -> np.ndarray:
    """Height of the distant terrain (deg above the true horizon) at azimuth ``az_rad``."""
    if model.terrain_deg <= 0:
        return np.zeros_like(az_rad)
    rng = np.random.default_rng(model.terrain_seed)
    k = np.arange(1, 9)
    amp = rng.uniform(0.2, 1.0, k.size) / k
    ph = rng.uniform(0, 2 * np.pi, k.size)
    h = np.zeros_like(az_rad)
    for kk, a, p in zip(k, amp, ph):
        h = h + a * np.cos(kk * az_rad + p)
    span = amp.sum()
    return (model.terrain_deg * 0.5 * (h / span + 1.0)).astype(az_rad.dtype)


def ground_and_horizon(model: SkyModel, dirs_enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parts that do not move with the sun: ``is_sky`` (N,) above the terrain, and the
    ground's radiance (N, 3) at full daylight."""
    d = dirs_enu
    az = np.arctan2(d[:, 0], d[:, 1])
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))
    is_sky = el > terrain_elevation_deg(model, az)
    tex = 1.0 + 0.15 * np.sin(23.0 * az) * np.cos(40.0 * d[:, 2])
    ground = ((model.ground_level * tex)[:, None] * GROUND).astype(np.float32)
    return is_sky, ground


def sky_radiance(
    model: SkyModel,
    dirs_enu: np.ndarray,
    sun_enu: np.ndarray,
    sun_el_deg: float,
    is_sky: np.ndarray,
    ground: np.ndarray,
) -> np.ndarray:
    """RGB radiance (N, 3) float32 of the clear sky, and of the ground where ``is_sky`` is
    False, for ENU unit directions (N, 3) (see :func:`ground_and_horizon`)."""
    d = dirs_enu
    cz = d[:, 2]
    cos_chi = np.clip(d @ sun_enu.astype(np.float32), -1.0, 1.0)
    chi = np.arccos(cos_chi)
    # normalised to the dome's mean radiance (not the zenith's, which for a high sun lies in
    # the aureole), so a camera's auto-exposure sees a similar sky all day
    rel = _indicatrix(chi) * _gradation(cz) / _dome_mean(sun_enu)
    # whiteness: near the sun (aureole) and near the horizon (long path)
    aureole = np.exp(-chi / 0.35)
    horizon = np.exp(-np.maximum(cz, 0.0) / 0.12)
    w = np.clip(0.12 + 0.75 * aureole + 0.45 * horizon, 0.0, 1.0)[:, None]
    colour = (1.0 - w) * BLUE + w * WHITE
    # the sky's brightness follows the clear-sky diffuse irradiance (relative to the zenith
    # sun's): 25 + 90 sqrt(sin(el)) W m-2
    day = (25.0 + 90.0 * float(np.sqrt(max(np.sin(np.radians(sun_el_deg)), 0.0)))) / 115.0
    L = (model.zenith_level * day * rel)[:, None] * colour
    L = np.where(is_sky[:, None], L, ground * day)
    return L.astype(np.float32)
