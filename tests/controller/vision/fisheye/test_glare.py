"""The rim's crossings along each ray (controller.vision.fisheye.glare._crossings)."""

import numpy as np

from controller.vision.fisheye.glare import _crossings


def test_each_rays_first_fall_below_its_level_is_interpolated():
    radii = np.arange(10) * 0.5
    falling = 250.0 - 25.0 * np.arange(10)  # 250 .. 25
    vals = np.tile(falling, (6, 1))
    level = np.array([125.0, 240.0, 125.0, 125.0, 125.0, 260.0])
    vals[2, 5:] = np.nan  # the fall's lower sample unknown: no rim
    vals[3, :] = 200.0  # never falls below its level, nor from the first sample
    vals[4, 3] = 100.0  # a dip before the fall: the first fall counts
    chi, has, slope = _crossings(vals, radii, level)
    assert has.tolist() == [True, True, False, False, True, False]  # the last starts below
    np.testing.assert_allclose(chi[[0, 1, 4]], [2.5, 0.2, 1.0 + 0.5 * (200.0 - 125.0) / 100.0])
    np.testing.assert_allclose(slope[[0, 1]], [50.0, 50.0])  # grey levels per unit of radius
    np.testing.assert_allclose(slope[4], 200.0)
