"""Saturated streaks along the sensor's columns (controller.vision.fisheye.streak) and the
sky's dipole fitted on part of the circle (skybg)."""

import math

import numpy as np
import pytest

from controller.vision.fisheye import FisheyeLens
from controller.vision.fisheye.skybg import sky_dipole
from controller.vision.fisheye.sphere import tangent_basis
from controller.vision.fisheye.streak import (
    core_row,
    rays_towards,
    short_bloom_both_ways,
    streak_along,
    streak_along_at_core,
    streak_rays,
    streak_sides_at_core,
    streak_way,
)

SAT = 252.0


def _glare(x0=100.0, y0=100.0, r=8.0, size=200):
    """A saturated disk of radius ``r`` on a sky of 120."""
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    img = np.full((size, size), 120.0)
    img[np.hypot(xx - x0, yy - y0) <= r] = 255.0
    return img, xx, yy


def _bloom(img, xx, yy, x0, y0, r, way, length=2.0):
    """Spill from each saturated column of the disk, ``way`` -1 up or +1 down, over a length
    that tapers towards the disk's sides (as the second renderer's bloom does)."""
    for c in range(int(x0 - r), int(x0 + r) + 1):
        half = math.sqrt(max(r * r - (c - x0) ** 2, 0.0))
        if half <= 0:
            continue
        spill = length * r * math.sqrt(half / r)
        edge = y0 + way * half
        lo, hi = sorted((edge, edge + way * spill))
        img[int(lo) : int(hi) + 1, c] = 255.0
    return img


def test_the_core_row_is_the_saturated_run_through_the_centre():
    img, _, _ = _glare(100.0, 100.0, 8.0)
    img[100, 97] = 200.0  # one noisy pixel is bridged
    xc, rc = core_row(img, 101.0, 100.0, SAT)
    assert xc == pytest.approx(100.0, abs=0.5)
    assert rc == pytest.approx(8.5, abs=0.6)
    assert core_row(img, 150.0, 100.0, SAT)[1] == 0.0  # not in the core


def test_a_streak_one_way_is_told_from_both_ways_and_from_none():
    for way, expected in ((-1, -1.0), (1, 1.0)):
        img, xx, yy = _glare()
        _bloom(img, xx, yy, 100.0, 100.0, 8.0, way)
        assert streak_way(streak_sides_at_core(img, 100.3, 100.2, SAT)) == expected
    img, xx, yy = _glare()
    _bloom(_bloom(img, xx, yy, 100.0, 100.0, 8.0, -1), xx, yy, 100.0, 100.0, 8.0, 1)
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) == 0.0
    img, _, _ = _glare()
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) is None


def test_a_short_streak_one_way_is_found_by_how_far_the_core_runs_on():
    """A spill reaching 0.6 radii past the disk: not saturated out to 2 radii, so only the
    core's column running on past where it stops the other way tells it (a one-radius
    bloom on the second renderer read 0.080 deg RMS before, 0.033 after)."""
    img, xx, yy = _glare()
    _bloom(img, xx, yy, 100.0, 100.0, 8.0, -1, length=0.6)
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) == -1.0
    img, xx, yy = _glare()
    _bloom(img, xx, yy, 100.0, 100.0, 8.0, 1, length=0.6)
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) == 1.0
    img, xx, yy = _glare()
    img[(yy < 100.0) & (yy > 86.0) & (np.abs(xx - 100.0) < 1.5)] = 255.0  # a thread, not a spill
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) is None


def test_a_sunlit_cloud_edge_leaving_the_glare_is_not_a_streak():
    """A thin saturated edge leaving the glare up and aside, and a saturated cloud wider than
    the glare above it: neither is a column streak (on our broken-cloud suite a looser test
    missed 14 visible suns instead of 9)."""
    img, xx, yy = _glare()
    edge = (np.abs((xx - 100.0) + 0.6 * (yy - 100.0)) < 2.0) & (yy < 100.0)
    img[edge] = 255.0
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) is None
    img, xx, yy = _glare()
    img[(yy < 95.0) & (yy > 70.0) & (np.abs(xx - 100.0) < 30.0)] = 255.0
    assert streak_way(streak_sides_at_core(img, 100.0, 100.0, SAT)) is None


def test_the_rays_towards_a_streak_are_those_within_40_deg_of_the_images_vertical():
    lens = FisheyeLens(np.array([[160.0, 0, 319.5], [0, 160.0, 239.5], [0, 0, 1]]), np.zeros(4), 640, 480)
    a = np.array([0.3, -0.4, 0.0])
    a[2] = math.sqrt(1 - a @ a)
    e1, e2 = tangent_basis(a)
    phi = np.arange(72) * (2 * math.pi / 72)
    rho = math.radians(3.0)
    up = rays_towards(lens, a, e1, e2, phi, rho, -1.0)
    down = rays_towards(lens, a, e1, e2, phi, rho, 1.0)
    pts = math.cos(rho) * a + math.sin(rho) * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    uv, _ = lens.project(np.vstack([a[None, :], pts]))
    ang = np.degrees(np.arctan2(uv[1:, 0] - uv[0, 0], -(uv[1:, 1] - uv[0, 1])))  # from image-up
    assert np.array_equal(up, np.abs(ang) < 40.0)
    assert np.array_equal(down, np.abs(ang) > 140.0)
    assert 14 <= up.sum() <= 18 and not (up & down).any()


def test_a_short_bloom_both_ways_is_a_rim_pushed_out_up_and_down_alone():
    """The rays within 50 deg of the image's vertical, up and down alike, reach beyond the
    fitted rim (a third of them at least) while the others keep to it: a short spill both
    ways.  Misses on one side only (a cloud's edge), inwards (a dark cloud) or across the
    columns (a rough fleck) are not."""
    lens = FisheyeLens(np.array([[160.0, 0, 319.5], [0, 160.0, 239.5], [0, 0, 1]]), np.zeros(4), 640, 480)
    a = np.array([0.0, 0.0, 1.0])  # the image's centre: e1 is the image's x, e2 its y (down)
    e1, e2 = tangent_basis(a)
    phi = np.arange(48) * (2 * math.pi / 48)
    rho = math.radians(1.3)
    geometry = (lens, a, e1, e2, phi, rho)
    off_vertical = np.degrees(np.arccos(np.abs(np.sin(phi))))
    up, down = np.sin(phi) < 0, np.sin(phi) > 0

    def rim(out_up, out_down, push=1.3, out_across=0):
        """Each ray's rim (rad), whether it found one, whether the fit kept it."""
        chi, kept = np.full(48, rho), np.ones(48, bool)
        for rays, n in ((up & (off_vertical < 30.0), out_up), (down & (off_vertical < 30.0), out_down),
                        (off_vertical > 60.0, out_across)):  # fmt: skip
            out = np.flatnonzero(rays)[:n]
            chi[out] *= push
            kept[out] = False
        return chi, np.ones(48, bool), kept

    assert short_bloom_both_ways(geometry, *rim(6, 6))
    assert not short_bloom_both_ways(geometry, *rim(6, 0))  # one side: a cloud's edge
    assert not short_bloom_both_ways(geometry, *rim(6, 6, push=0.7))  # inwards: a dark cloud
    assert not short_bloom_both_ways(geometry, *rim(6, 6, out_across=5))  # rough all round: a fleck


def test_a_streak_along_the_images_rows_is_found_as_one_along_its_columns():
    """A frame turned 90 deg (a sensor read out across the stored image): the streak runs
    along the rows, and is found on that axis, its way by the column coordinate, with the
    same answers as the frame before the turn."""
    for way in (-1, 1):
        img, xx, yy = _glare()
        _bloom(img, xx, yy, 100.0, 100.0, 8.0, way)
        assert streak_along_at_core(img, 100.3, 100.2, SAT) == (float(way), 1)
        assert streak_along_at_core(np.ascontiguousarray(img.T), 100.2, 100.3, SAT) == (float(way), 0)
    img, xx, yy = _glare()
    _bloom(_bloom(img, xx, yy, 100.0, 100.0, 8.0, -1, 3.0), xx, yy, 100.0, 100.0, 8.0, 1, 3.0)
    assert streak_along(img, 100.0, 100.0, 8.0, SAT) == (0.0, 1)
    assert streak_along(np.ascontiguousarray(img.T), 100.0, 100.0, 8.0, SAT) == (0.0, 0)
    img, _, _ = _glare()
    assert streak_along(img, 100.0, 100.0, 8.0, SAT)[0] is None
    assert streak_along_at_core(img, 100.0, 100.0, SAT)[0] is None


def test_a_streak_takes_the_rays_along_its_axis():
    """Both ways: the rays within 50 deg of its axis, by design; one way: those towards it
    (within 40 deg of the image's axis, that way)."""
    lens = FisheyeLens(np.array([[160.0, 0, 319.5], [0, 160.0, 239.5], [0, 0, 1]]), np.zeros(4), 640, 480)
    a = np.array([0.0, 0.0, 1.0])  # the image's centre: e1 is the image's x
    e1, e2 = tangent_basis(a)
    phi = np.arange(72) * (2 * math.pi / 72)
    rho = math.radians(3.0)
    deg = np.degrees(phi)
    for axis, along in ((1, np.abs(np.sin(phi))), (0, np.abs(np.cos(phi)))):
        ok, usable = streak_rays((lens, a, e1, e2, phi, rho), 0.0, axis)
        assert np.array_equal(ok, along < math.sin(math.radians(50))) and np.array_equal(usable, ok)
    ok, usable = streak_rays((lens, a, e1, e2, phi, rho), 1.0, 0)  # rightwards only
    off = np.minimum(deg, 360.0 - deg)  # from the image's +x
    assert ok.all() and not usable[off < 39.0].any() and usable[off > 41.0].all()
    ok, usable = streak_rays((lens, a, e1, e2, phi, rho), None, 0)
    assert ok.all() and usable.all()


def test_the_skys_dipole_is_fitted_on_the_part_of_the_circle_a_streak_leaves():
    """A streak's sector (80 deg) out of the rings, and a few more rays lost to the ground:
    the dipole is still the sky's.  When the rings' share was counted over every ray, such
    rings were all dropped and the dipole read as none (a one-way bloom on the second
    renderer: 0.1-0.8 deg low at 18-35 deg elevation)."""
    rho = math.radians(3.5)
    chi = np.linspace(1.15 * rho, 3.2 * rho, 24)
    phi = np.arange(36) * (2 * math.pi / 36)
    profile = 60.0 * np.exp(-(chi / rho - 1.0) * 3.0)  # the glare's own wing
    k = np.array([12.0, -7.0])  # grey levels per rho along cos, sin
    vals = (
        100.0 + profile[None, :] + (chi / rho)[None, :] * (k[0] * np.cos(phi) + k[1] * np.sin(phi))[:, None]
    )
    up = np.abs(((np.degrees(phi) - 270.0 + 180.0) % 360.0) - 180.0) < 40.0
    sky = np.ones(vals.shape, bool)
    sky[(np.degrees(phi) > 60) & (np.degrees(phi) < 95)] = False  # the ground's wedge
    dip = sky_dipole(vals, chi, phi, rho, ~up, 150.0, sky)
    assert dip == pytest.approx(k, abs=0.5)


def test_a_columns_run_is_the_row_by_row_walks():
    """The saturated run along the core's column, read in one reduction, is what walking
    row by row gives: one unsaturated row bridged, two end it, the frame's edge ends it."""
    from controller.vision.fisheye.streak import _column_run

    def walk(grey, x0, x1, y0, step, sat):
        y, n, gap = y0, 0, 0
        while 0 <= y + step < grey.shape[0] and gap < 2:
            y += step
            if grey[y, x0:x1].max() >= sat:
                n, gap = n + 1 + gap, 0
            else:
                gap += 1
        return n

    rng = np.random.default_rng(5)
    for _ in range(3000):
        H = int(rng.integers(1, 25))
        grey = ((rng.random((H, 6)) < rng.uniform(0.2, 1.0)) * 255).astype(np.uint8)
        y0, x0 = int(rng.integers(0, H)), int(rng.integers(0, 3))
        x1 = x0 + 1 + int(rng.integers(0, 3))
        for step in (-1, 1):
            assert _column_run(grey, x0, x1, y0, step, 250) == walk(grey, x0, x1, y0, step, 250)
