"""The second renderer's sky (:mod:`benchmarks.fisheye_other`): the CIE general sky types of
ISO 15469 / CIE S 011 (luminance = gradation(zenith angle) x indicatrix(angle from the sun)),
and a circumsolar region that falls as a power law, so that the default fisheye pipeline is
judged on skies of other shapes than the one it was developed on."""

from __future__ import annotations

import math

import numpy as np

# ISO 15469 / CIE S 011 general sky types: (a, b) gradation, (c, d, e) indicatrix
CIE_SKY_TYPES = {
    10: (-1.0, -0.55, 5.0, -2.5, 0.30),  # partly cloudy, brighter circumsolar region
    11: (-1.0, -0.55, 10.0, -3.0, 0.45),  # white-blue sky, distinct solar corona
    12: (-1.0, -0.32, 10.0, -3.0, 0.45),  # the CIE standard clear sky, low luminance turbidity
    13: (-1.0, -0.32, 16.0, -3.0, 0.30),  # clear sky, polluted atmosphere
    15: (-1.0, -0.15, 24.0, -2.8, 0.15),  # cloudless turbid sky, broad solar corona
}


def cie_clear(zen: np.ndarray, chi: np.ndarray, zen_sun: float, sky_type: int | str = 12) -> np.ndarray:
    """Sky luminance relative to the zenith's: a CIE general sky type (12: the standard clear
    sky), or ``"power"``: the type 12 gradation over a circumsolar region that falls as
    ``chi^-1.5`` (as measured aureoles and sunshape models do) rather than ``exp(-3 chi)``."""
    if sky_type == "power":
        a, b = CIE_SKY_TYPES[12][:2]

        def ind(x):
            return (
                1
                + 0.45 * np.cos(x) ** 2
                + 3.0 * (np.maximum(x, math.radians(0.5)) / math.radians(10)) ** -1.5
            )

    else:
        a, b, c, d, e = CIE_SKY_TYPES[int(sky_type)]

        def ind(x):
            return 1 + c * (np.exp(d * x) - math.exp(d * math.pi / 2)) + e * np.cos(x) ** 2

    def grad(z):
        return 1 + a * np.exp(b / np.maximum(np.cos(z), 0.01))

    return ind(chi) * grad(zen) / (ind(np.array(zen_sun)) * grad(np.array(0.0)))


# sky_level that gives a sky type the luminance of type 12 3 deg below a sun at 28 deg
SAME_LEVEL: dict[int | str, float] = {13: 0.74, 15: 0.56, 10: 1.86, "power": 0.47}
SKIES = (
    (13, "CIE sky type 13"),
    (15, "CIE sky type 15"),
    (10, "CIE sky type 10"),
    ("power", "power-law aureole"),
)
