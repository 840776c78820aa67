"""The sun's glare in the HIL sky camera: a saturated disk with a halo, and sensor smear.

At any exposure that shows the sky, the sun and its circumsolar aureole overexpose a disk
several degrees wide.  Its profile is a Moffat-like core with power-law wings,

    g(rho) = (1 + (rho / rho0)^2) ^ (-n / 2)          (rho: angle or pixel distance)

scaled so that ``g`` reaches full scale at ``radius_deg`` for the zenith sun, clear sky,
nominal exposure.  The saturated disk therefore grows with exposure and shrinks with cloud
transmittance and air mass: it is where ``X T A g(rho) = 1``.  Part of the profile is in
angle about the sun's direction (the aureole: round on the sky, squeezed by the fisheye near
the edge), part in pixels about the sun's image (lens veiling glare: round on the sensor);
``image_weight`` sets the mix.  A broad Gaussian halo adds the unsaturated falloff.

Smear (applied to the linear image before clipping):

* ``ccd``: frame-transfer smear; every column gets a constant proportional to the glare
  flux through it, so a vertical streak crosses the whole frame;
* ``bloom``: the charge that overflows saturated pixels spills along the column, so the
  saturated run extends above and below the disk by a length that grows with the excess.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SMEAR_KINDS = ("none", "ccd", "bloom")


@dataclass(frozen=True)
class GlareModel:
    """Parameters of the sun's glare.

    radius_deg : saturated radius (deg) for the zenith sun in a clear sky, nominal exposure.
    core_deg, power : Moffat ``rho0`` (deg) and wing exponent ``n``.
    image_weight : 0 = all in angle (aureole), 1 = all in pixels (lens glare).
    halo_level, halo_deg : broad Gaussian halo: peak (full scale) and 1/e radius (deg).
    smear, smear_level : ``"none" | "ccd" | "bloom"``; for ``ccd`` the streak level at the
        sun's column (full scale), for ``bloom`` the spill length in units of the disk radius.
    warm : colour of the glare's unsaturated edge at low sun (R, G, B weights at sunrise).
    """

    radius_deg: float = 3.2
    core_deg: float = 0.6
    power: float = 3.0
    image_weight: float = 0.25
    halo_level: float = 0.12
    halo_deg: float = 9.0
    smear: str = "none"
    smear_level: float = 0.0
    warm: tuple[float, float, float] = (1.0, 0.93, 0.80)

    def profile(self, rho_deg):
        return (1.0 + (np.asarray(rho_deg, np.float32) / self.core_deg) ** 2) ** (-self.power / 2.0)

    @property
    def amplitude(self) -> float:
        """Peak signal (full scale = 1) of the zenith sun at the nominal exposure."""
        return float(1.0 / self.profile(self.radius_deg))


def air_mass_dimming(el_deg: float) -> float:
    """Direct-beam transmittance relative to the zenith sun (Meinel, Kasten-Young air mass)."""
    if el_deg <= -0.8:
        return 0.0
    z = np.radians(90.0 - max(el_deg, -0.8))
    am = 1.0 / (np.cos(z) + 0.50572 * (96.07995 - np.degrees(z)) ** -1.6364)
    return float(0.7 ** (am**0.678) / 0.7)


def glare_signal(
    model: GlareModel,
    chi_deg: np.ndarray,
    pix_deg: np.ndarray,
    strength: float,
    aureole_transmittance: np.ndarray | float = 1.0,
) -> np.ndarray:
    """Glare (full-scale units, unclipped) of a source of relative ``strength`` (X T A).

    ``chi_deg``: angle of each view from the source (deg); ``pix_deg``: pixel distance from the
    source's image converted to degrees with the lens's central scale; the angle part is
    multiplied by ``aureole_transmittance`` (cloud in the line of sight of each pixel).
    """
    w = model.image_weight
    core = (1.0 - w) * model.profile(chi_deg) * aureole_transmittance + w * model.profile(pix_deg)
    halo = model.halo_level * np.exp(-((chi_deg / model.halo_deg) ** 2)) / model.amplitude
    return (strength * (core + halo)).astype(np.float32)


def apply_smear(
    model: GlareModel,
    signal: np.ndarray,
    glare: np.ndarray,
    roi: tuple[int, int, int, int],
) -> np.ndarray:
    """Add the sensor's smear to ``signal`` (H, W, 3) in place; ``glare`` is the sun's glare
    in ``roi = (r0, r1, c0, c1)`` (single channel, full-scale units)."""
    if model.smear == "none" or model.smear_level <= 0:
        return signal
    r0, r1, c0, c1 = roi
    if model.smear == "ccd":
        flux = glare.sum(axis=0)
        if flux.max() <= 0:
            return signal
        streak = model.smear_level * flux / flux.max()
        signal[:, c0:c1, :] += streak[None, :, None]
        return signal
    # bloom: overflow charge of each column spills up and down from its saturated run
    excess = np.maximum(glare - 1.0, 0.0)
    radius_px = max(np.sqrt((glare >= 1.0).sum() / np.pi), 1.0)
    total = excess.sum(axis=0)
    if total.max() <= 0:
        return signal
    length = model.smear_level * radius_px * np.sqrt(total / total.max())
    rows = np.arange(r0, r1)[:, None]
    sat = glare >= 1.0
    has = np.asarray(sat.any(axis=0))
    top = np.where(has, np.argmax(sat, axis=0), 0) + r0
    bot = np.where(has, r1 - 1 - np.argmax(sat[::-1], axis=0), 0)
    above = np.clip(1.0 - (top[None, :] - rows) / np.maximum(length[None, :], 1e-6), 0.0, 1.0)
    below = np.clip(1.0 - (rows - bot[None, :]) / np.maximum(length[None, :], 1e-6), 0.0, 1.0)
    spill = np.where(rows < top[None, :], above, np.where(rows > bot[None, :], below, 0.0))
    spill = np.where(has[None, :], spill, 0.0) * 1.5
    signal[r0:r1, c0:c1, :] += spill[:, :, None].astype(np.float32)
    return signal
