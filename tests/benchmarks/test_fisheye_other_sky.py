"""The second renderer's sky shapes (benchmarks.fisheye_other_sky)."""

import math

import numpy as np
import pytest

from benchmarks.fisheye_other_sky import SAME_LEVEL, SKIES, cie_clear

ZS = math.radians(62.0)  # a sun at 28 deg elevation


def _at(dz_deg: float, sky_type) -> float:
    """Luminance ``dz_deg`` from the sun along its vertical (positive: towards the horizon)."""
    z = np.array(ZS + math.radians(dz_deg))
    return float(cie_clear(z, np.array(math.radians(abs(dz_deg))), ZS, sky_type))


@pytest.mark.parametrize("sky_type", [k for k, _ in SKIES])
def test_each_sky_is_brought_to_the_standard_clear_skys_circumsolar_level(sky_type):
    assert SAME_LEVEL[sky_type] * _at(3.0, sky_type) == pytest.approx(_at(3.0, 12), rel=0.02)


@pytest.mark.parametrize("sky_type", [12, 13, 15, 10, "power"])
def test_next_to_the_sun_every_sky_is_brighter_towards_the_horizon(sky_type):
    assert _at(4.0, sky_type) > _at(-4.0, sky_type)


def test_the_power_law_aureole_is_steeper_next_to_the_sun_than_the_cie_one():
    steep = {k: _at(2.0, k) / _at(8.0, k) for k in (12, 15, "power")}
    assert steep["power"] > 1.5 * max(steep[12], steep[15])
    assert cie_clear(np.array(0.3), np.array(0.2), 0.3, 12) == pytest.approx(
        cie_clear(np.array(0.3), np.array(0.2), 0.3)
    )
