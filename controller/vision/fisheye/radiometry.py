"""Grey levels to light and back, and the lens's relative illumination (the bundle's
``[radiometry]``).

The rim of the glare is read where the grey level is near the clip, while the sky that
shifts it is measured a few radii out, far lower.  Sums of light are only sums in linear
units: on an sRGB camera a sky gradient measured in grey at the sky's level is about twice
what it adds at the rim's level (the curve's slope there is half), and a lens that darkens
towards the edge of the field dims the glare's outer side as much as the sky's, in
proportion to the glare's own level.  :func:`.glare.fit_glare` therefore models the sky in
light, undone of the vignetting, and turns each ray's rim level back into grey here.

Light is scaled so that grey 255 is light 255; grey 0 is the table's first value (0 for the
named curves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...calibration.fisheye_bundle import RadiometryCal, relative_illumination

_GREY = np.linspace(0.0, 255.0, 4097)


def _srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding, 0-1 to 0-1."""
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


@dataclass(frozen=True)
class Radiometry:
    """A camera's response (a monotone table, grey to light) and vignetting coefficients."""

    grey_levels: np.ndarray  # increasing grey levels, 0..255
    light: np.ndarray  # strictly increasing light at those levels, 255 at grey 255
    vignetting: tuple[float, ...] = ()

    @classmethod
    def from_cal(cls, cal: RadiometryCal | None) -> Radiometry | None:
        """The runtime form of a bundle's ``[radiometry]``; None when the frame is linear and
        evenly lit (nothing to convert)."""
        if cal is None or (cal.response == "linear" and not cal.vignetting):
            return None
        x = _GREY / 255.0
        if cal.response == "srgb":
            y = _srgb_to_linear(x)
        elif cal.response == "gamma":
            y = x ** float(cal.gamma or 1.0)
        elif cal.response == "table":
            y = np.interp(_GREY, np.arange(256.0), np.asarray(cal.table, float))
        else:
            y = x
        # strictly increasing, so that light -> grey is a function (a measured table may be
        # flat where the camera clips or crushes its blacks)
        y = np.maximum.accumulate(y) + np.arange(y.size) * 1e-9
        return cls(_GREY.copy(), 255.0 * y / y[-1], tuple(cal.vignetting))

    def to_light(self, grey: np.ndarray | float) -> np.ndarray:
        """Light for grey levels (clipped to 0..255)."""
        return np.interp(np.asarray(grey, float), self.grey_levels, self.light)

    def to_grey(self, light: np.ndarray | float) -> np.ndarray:
        """Grey levels for light (clipped to the table's range)."""
        return np.interp(np.asarray(light, float), self.light, self.grey_levels)

    def illumination(self, cos_theta: np.ndarray | float) -> np.ndarray:
        """Relative illumination at field angles whose cosines are ``cos_theta``
        (camera z is the optical axis)."""
        return relative_illumination(self.vignetting, np.asarray(cos_theta, float))


def illumination_about(
    radiometry: Radiometry, a: np.ndarray, e1: np.ndarray, e2: np.ndarray, phi: np.ndarray, chi: np.ndarray
) -> np.ndarray:
    """The lens's illumination at the samples (``phi``, ``chi``) about ``a`` (n_phi, n_chi),
    relative to the illumination at ``a``."""
    tz = np.cos(phi) * e1[2] + np.sin(phi) * e2[2]
    z = np.cos(chi)[None, :] * a[2] + np.sin(chi)[None, :] * tz[:, None]
    return radiometry.illumination(z) / radiometry.illumination(float(a[2]))


def rim_shift(
    radiometry: Radiometry | None,
    shift_s: np.ndarray,
    base: float,
    a: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    phi: np.ndarray,
    rho: float,
) -> np.ndarray:
    """Each ray's raise of the rim's grey level over ``base`` (grey): the sky's asymmetry
    ``shift_s`` in the sky model's units, added in light to the base level's light and dimmed
    by the lens's illumination at the rim, then turned back into grey.  Without a
    radiometry, the frame is linear and evenly lit: the shift itself."""
    if radiometry is None:
        return shift_s
    vig = illumination_about(radiometry, a, e1, e2, phi, np.array([rho]))[:, 0]
    return np.asarray(radiometry.to_grey(vig * (radiometry.to_light(base) + shift_s)), float) - base
