"""The sky behind a glare's rim (controller.vision.fisheye.rimsky): its reading on the rings
outside the rim, and each ray's rim level raised by it."""

import math
from dataclasses import replace

import numpy as np
import pytest

from controller.vision.fisheye.glare import GlareOptions
from controller.vision.fisheye.rimsky import SkyBehind, read_sky, rim_levels
from controller.vision.fisheye.sphere import tangent_basis

RHO = math.radians(3.0)
N_RAYS = 36
PHI = np.arange(N_RAYS) * (2 * math.pi / N_RAYS)
CHI = np.linspace(1.15 * RHO, 3.2 * RHO, 24)
PEAK = 255.0


def rings(gradient: float = 6.0, sky_level: float = 40.0, glare: float = 120.0):
    """A glare's falling profile over a sky ``sky_level`` grey that brightens by ``gradient``
    grey per rim radius towards the rays at phi = 0 (grey samples, all on the sky)."""
    c = CHI / RHO
    vals = (
        sky_level + glare * np.exp(-3.0 * (c - 1.0))[None, :] + gradient * c[None, :] * np.cos(PHI)[:, None]
    )
    return vals, np.ones(vals.shape, bool)


def geometry():
    a = np.array([0.0, 0.0, 1.0])
    e1, e2 = tangent_basis(a)
    return (None, a, e1, e2, PHI, RHO)


def read(samples, before=None, opts=None, first=False):
    return read_sky(
        samples,
        CHI,
        geometry(),
        np.ones(N_RAYS, bool),
        None,
        PEAK,
        opts or GlareOptions(),
        before or SkyBehind(),
        first=first,
        streak_free=True,
        alpha=0.0,
        dpp=0.3,
        up_cam=None,
        radiometry=None,
    )


def test_a_sky_brightening_towards_one_side_raises_the_rims_level_on_that_side():
    sky = read(rings(gradient=6.0))
    assert sky is not None and sky.by_el is None
    assert sky.dipole[0] == pytest.approx(6.0, abs=0.3) and abs(sky.dipole[1]) < 0.3
    opts = GlareOptions()
    level, shift, shift_s = rim_levels(sky, geometry(), None, PEAK, opts, None, None)
    base = sky.bg + opts.level * (PEAK - sky.bg)
    assert np.argmax(shift) == 0 and np.argmin(shift) == N_RAYS // 2  # bright side up, dark side down
    assert shift[0] == pytest.approx(sky.dipole[0]) and np.allclose(shift, shift_s)
    assert np.allclose(level, base + shift)
    # the camera's sky scale multiplies the raise
    twice, _, _ = rim_levels(sky, geometry(), None, PEAK, replace(opts, sky_scale=2.0), None, None)
    assert np.allclose(twice - base, 2.0 * shift)


def test_an_even_sky_leaves_the_rim_level_where_the_level_puts_it():
    sky = read(rings(gradient=0.0))
    assert sky is not None
    assert np.linalg.norm(sky.dipole) < 0.05
    level, _, _ = rim_levels(sky, geometry(), None, PEAK, GlareOptions(), None, None)
    assert np.allclose(level, sky.bg + 0.85 * (PEAK - sky.bg), atol=0.05)
    assert sky.bg == pytest.approx(float(np.median(rings(gradient=0.0)[0][:, -3:])))


def test_rings_that_see_too_little_sky_are_no_reading():
    vals, seen = rings()
    seen[:, -3:] = False
    seen[:3, -3:] = True  # 9 outer samples of which only some are finite
    vals[:3, -3:] = np.nan
    assert read((vals, seen)) is None


def test_the_clear_skys_trust_is_judged_once_centred_and_kept_before():
    cal = replace(GlareOptions(), sky_calibration=(1.0, 0.0, 1.0, 0.0))
    before = SkyBehind(trust=0.3)
    assert read(rings(), before, cal, first=True).trust == 0.3  # the first pass: kept
    assert read(rings(), before, GlareOptions()).trust == 0.3  # no calibration to trust
    assert read(rings(), before, cal).trust == 1.0  # a smooth clear sky: trusted in full


def test_a_reading_whose_inner_rings_reach_the_rims_level_was_read_inside_the_glare():
    assert not read(rings()).inside
    vals, seen = rings()
    vals[:, CHI < 1.4 * RHO] = PEAK
    assert read((vals, seen)).inside
