"""The sun placed by the sky's rings, for a camera whose sky is a product (rings)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.vision.fisheye import rings
from controller.vision.fisheye.rings import SkyReading, log_ring_offset, ring_direction

from .helpers import E1, E2, RHO, A, angle_deg, product_sky


def reading_of(vals, chi, phi, sky=None) -> SkyReading:
    """The rings as a fit's last reading of the sky keeps them (every ray counts)."""
    sky = np.ones(vals.shape, bool) if sky is None else sky
    return SkyReading(vals, chi, phi, RHO, np.ones(phi.size, bool), sky, A, E1, E2, 6000.0)


@pytest.mark.parametrize(
    ("eps_deg", "el_deg"), [((0.0, 0.0), 30.0), ((0.08, -0.12), 30.0), ((-0.1, 0.05), 15.0)]
)
def test_the_rings_place_the_sun_in_a_product_sky(eps_deg, el_deg):
    eps = tuple(math.radians(e) for e in eps_deg)
    vals, chi, phi, up, x = product_sky(eps, el_deg)
    ok = np.ones(phi.size, bool)
    got = log_ring_offset(reading_of(vals, chi, phi), x)
    assert got is not None
    assert np.degrees(np.abs(got - np.array(eps))).max() < 0.01
    # the reading as the pipeline keeps it: the direction, and the same offset
    reading = SkyReading(vals, chi, phi, RHO, ok, np.ones(vals.shape, bool), A, E1, E2, 30.0 * 200.0)
    d = ring_direction(reading, up)
    want = A + eps[0] * E1 + eps[1] * E2
    assert d is not None
    assert math.degrees(math.acos(min(1.0, float(d @ (want / np.linalg.norm(want)))))) < 0.01


@pytest.mark.parametrize("el_deg", [12.0, 16.0, 20.0])
def test_a_wide_glares_rings_follow_a_clear_skys_gradation_down_to_the_horizon(monkeypatch, el_deg):
    """A 7-deg rim's rings span 40 deg of CIE sky 12's gradation (a = -1, b = -0.32), which
    bends hardest near the horizon: the knots every 5 deg of elevation place a sun 0.2 deg
    off the axis to 0.01 deg; one cubic, as before them, leaves it 0.018-0.16 deg off."""
    rho, eps = math.radians(7.0), (0.0, math.radians(0.2))
    vals, chi, phi, up, x = product_sky(eps, el_deg, gradation_ab=(-1.0, -0.32), rho=rho)
    sky = (np.cos(chi)[None, :] * up[2] + np.sin(chi)[None, :] * np.sin(phi)[:, None] * up[1]) > 0
    reading = SkyReading(vals, chi, phi, rho, np.ones(phi.size, bool), sky, A, E1, E2, 6000.0)
    got = log_ring_offset(reading, x)
    assert got is not None and np.degrees(np.abs(got - np.array(eps))).max() < 0.01
    monkeypatch.setattr(rings, "KNOT_DEG", 1e3)  # no knot: one cubic over the rings
    one_cubic = log_ring_offset(reading, x)
    assert one_cubic is not None and math.degrees(abs(float(one_cubic[1]) - eps[1])) > 0.015


def test_in_an_additive_sky_the_rings_are_off_which_is_why_the_choice_is_learned():
    vals, chi, phi, up, x = product_sky((0.0, 0.0), 30.0, additive=True)
    got = log_ring_offset(reading_of(vals, chi, phi), x)
    assert got is not None and math.degrees(float(np.hypot(*got))) > 0.02


def test_too_little_sky_places_nothing():
    vals, chi, phi, up, x = product_sky((0.0, 0.0))
    sky = np.zeros(vals.shape, bool)
    sky[:4] = True  # four rays on the sky: no ring has six
    assert log_ring_offset(reading_of(vals, chi, phi, sky=sky), x) is None
    assert log_ring_offset(reading_of(np.zeros_like(vals), chi, phi), x) is None  # no light


def test_rough_rings_or_a_far_fix_place_nothing_and_a_small_cloud_is_left_out():
    vals, chi, phi, up, x = product_sky((0.0, 0.0))
    ok, sky = np.ones(phi.size, bool), np.ones(vals.shape, bool)

    def clouded(rays: slice, factor: float) -> SkyReading:
        cloud = vals.copy()
        cloud[rays, chi > 2.0 * RHO] *= factor  # a cloud over part of the outer rings
        return SkyReading(cloud, chi, phi, RHO, ok, sky, A, E1, E2, 6000.0)

    small = ring_direction(clouded(np.s_[5:12], 0.4), up)  # its rays clipped from the fit
    assert small is not None and angle_deg(small, A) < 0.01
    assert ring_direction(clouded(np.s_[0:18], 0.4), up) is None  # half the rings: 1.2 deg off
    assert ring_direction(clouded(np.s_[0:36:2], 0.2), up) is None  # rougher than a clear sky
    far = product_sky((math.radians(0.5), 0.0))[0]  # the rings put the sun 0.5 deg off the axis
    assert ring_direction(SkyReading(far, chi, phi, RHO, ok, sky, A, E1, E2, 6000.0), up) is None


def test_a_smooth_sky_lets_the_rings_move_a_wide_rim_by_its_share_of_the_radius(monkeypatch):
    """0.3 deg at most, or 7.5 % of the rim's radius (5 deg here: 0.375) where the rings are
    smooth: the sky's shift of a rim grows with its radius."""
    vals, chi, phi, up, _ = product_sky((math.radians(0.35), 0.0))
    reading = reading_of(vals, chi, phi)
    d = ring_direction(reading, up)
    want = A + math.radians(0.35) * E1
    assert d is not None and angle_deg(d, want) < 0.01
    monkeypatch.setattr(rings, "SMOOTH_ROUGHNESS", 0.0)  # as if a cloud roughened them
    assert ring_direction(reading, up) is None


def test_with_the_site_a_low_suns_rings_may_move_its_rim_by_a_share_growing_with_the_air_mass():
    """The sky's shift of a rim grows with the air mass too: with the site (the ephemeris
    gate behind the fix) a smooth sky's rings move a rim 20 deg high by up to 7.5 % of its
    radius times the air mass over 1.5 (twice that at most): 0.73 deg of a 5-deg rim there,
    0.375 without the site or for a sun 60 deg high."""
    vals, chi, phi, up, _ = product_sky((math.radians(0.6), 0.0), el_deg=20.0)
    reading = reading_of(vals, chi, phi)
    d = ring_direction(reading, up, by_airmass=True)
    assert d is not None and angle_deg(d, A + math.radians(0.6) * E1) < 0.01
    assert ring_direction(reading, up) is None  # without the site: 7.5 % of the radius
    vals, chi, phi, up, _ = product_sky((math.radians(0.6), 0.0), el_deg=60.0)
    assert ring_direction(reading_of(vals, chi, phi), up, by_airmass=True) is None
