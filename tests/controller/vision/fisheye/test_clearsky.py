"""A camera's sky calibration, fitted on clear days, applied as far as the rings around the
glare read a clear sky (clearsky)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.calibration.camera import CameraCal
from controller.vision.fisheye.clearsky import clear_sky_trust, cloud_edges, ring_roughness, trusted_scale
from controller.vision.fisheye.glare import GlareOptions, fit_glare
from controller.vision.fisheye.lens import FisheyeLens

RHO = 0.05  # the rim's radius (rad)
CAL = (2.5, 0.0, 2.5, 0.0)  # a camera whose clear sky asks for 2.5 times the model's correction


def rings(cloud: bool, seed: int) -> tuple[np.ndarray, ...]:
    """Rings 1.15-3.2 rim radii out: the glare's profile, a clear sky's dipole and a little
    quadrupole, noise; with ``cloud``, a cloud 50 grey levels dark over 40 deg of the rings
    beyond 2 radii."""
    rng = np.random.default_rng(seed)
    phi = np.arange(48) * (2 * math.pi / 48)
    chi = np.arange(1.15 * RHO, 3.2 * RHO, 0.02 * RHO)
    s = chi[None, :] / RHO
    vals = 60.0 + 120.0 * np.exp(-(chi - RHO) / (0.3 * RHO))[None, :]
    vals = vals + 4.0 * s * np.cos(phi - 0.7)[:, None] + 0.3 * s**2 * np.cos(2 * phi)[:, None]
    vals = vals + rng.normal(0.0, 0.7, vals.shape)
    if cloud:
        band = (np.abs(np.degrees(phi) - 100.0) < 20.0)[:, None] & (chi[None, :] > 2.0 * RHO)
        vals = np.where(band, vals - 50.0, vals)
    ok = np.ones(phi.size, bool)
    return vals, chi, phi, RHO, ok, np.ones(vals.shape, bool)


@pytest.mark.parametrize("seed", range(3))
def test_a_clear_skys_rings_are_smooth_and_a_clouds_are_not(seed):
    lo, hi = GlareOptions().clear_sky_roughness
    clear = ring_roughness(*rings(False, seed), 180.0)
    cloud = ring_roughness(*rings(True, seed), 180.0)
    assert clear is not None and cloud is not None
    assert clear < lo < hi < cloud
    assert clear_sky_trust(clear, lo, hi) == 1.0 and clear_sky_trust(cloud, lo, hi) == 0.0


def test_the_trust_falls_linearly_between_its_bounds_and_scales_the_departure_from_one():
    assert clear_sky_trust(0.35, 0.2, 0.5) == pytest.approx(0.5)
    assert clear_sky_trust(None, 0.2, 0.5) == 1.0  # rings that could not be judged
    assert trusted_scale(2.6, 0.5) == pytest.approx(1.8)
    assert trusted_scale(0.6, 0.0) == 1.0 and trusted_scale(2.6, 1.0) == 2.6


def test_rings_without_enough_sky_are_not_judged():
    vals, chi, phi, rho, ok, sky = rings(True, 0)
    sky[:40] = False  # the horizon takes all but 8 rays
    assert ring_roughness(vals, chi, phi, rho, ok, sky, 180.0) is None


def _scene(cloud: bool) -> tuple[np.ndarray, FisheyeLens, np.ndarray]:
    """A linear frame: a glare 3 deg wide (Moffat-like, 400 grey levels at its centre), a sky
    brightening across it (150 grey levels per radian), and with ``cloud`` a cloud 50 grey
    levels dark 5.5-9 deg from the sun over 40 deg of azimuth."""
    cam = CameraCal(
        width=320, height=240, fx=400.0, fy=400.0, cx=160.0, cy=120.0, dist=(0.0,) * 4, model="fisheye"
    )
    lens = FisheyeLens.from_camera(cam)
    u, v = np.meshgrid(np.arange(320.0), np.arange(240.0))
    d = lens.rays(np.stack([u.ravel(), v.ravel()], 1))[0].reshape(240, 320, 3)
    sun = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0])
    th = np.degrees(np.arccos(np.clip(d @ sun, -1.0, 1.0)))
    g = np.cross(sun, [0.0, 0.0, 1.0])
    g /= np.linalg.norm(g)
    img = 60.0 + 150.0 * (d @ g) + 400.0 * (1.0 + (th / 3.0) ** 2) ** -1.5
    if cloud:
        az = np.degrees(np.arctan2(d @ np.cross(sun, g), d @ g))
        img = img + np.where((np.abs(az - 40.0) < 20.0) & (th > 5.5) & (th < 9.0), -50.0, 0.0)
    return np.clip(img, 0.0, 255.0), lens, sun


@pytest.mark.parametrize("cloud", [False, True], ids=["clear", "cloud in the rings"])
def test_a_cameras_calibration_scales_a_clear_skys_correction_and_not_a_clouds(cloud):
    img, lens, sun = _scene(cloud)
    uv, _ = lens.project(sun[None, :])
    x0, y0 = float(uv[0, 0]), float(uv[0, 1])
    r_px = 2.7 / lens.deg_per_px(x0, y0)
    plain = fit_glare(img, lens, x0, y0, r_px, 255.0, GlareOptions())
    cal = fit_glare(img, lens, x0, y0, r_px, 255.0, GlareOptions(sky_calibration=CAL))
    assert plain is not None and cal is not None and "sky_dipole" in plain.flags
    apart = math.degrees(math.acos(min(1.0, float(plain.axis @ cal.axis))))
    if cloud:  # the sky model as it is, once the rings are judged (the first reading is not)
        assert apart < 0.005
    else:  # 1.5 times more correction than the model's own (0.08 deg here)
        assert apart > 0.05


def _roughness_band_by_band(vals, chi, phi, rho, rays_ok, sky, contrast):
    """The roughness as first written: each band's rays fitted by least squares in turn."""
    from controller.vision.fisheye.clearsky import DIPOLE_FLOOR, MIN_RING_RAYS, RING_BANDS

    good = sky & rays_ok[:, None] & np.isfinite(vals)
    A = np.stack([np.ones_like(phi), np.cos(phi), np.sin(phi), np.cos(2 * phi), np.sin(2 * phi)], 1)
    res2, dip2 = [], []
    for lo, hi in RING_BANDS:
        sel = (chi >= lo * rho) & (chi < hi * rho)
        if sel.sum() < 2:
            continue
        ok = good[:, sel].all(axis=1)
        if ok.sum() < MIN_RING_RAYS:
            continue
        m = vals[ok][:, sel].mean(axis=1)
        coef, *_ = np.linalg.lstsq(A[ok], m, rcond=None)
        res2.append(float(np.mean((m - A[ok] @ coef) ** 2)))
        dip2.append(float(coef[1] ** 2 + coef[2] ** 2))
    if not res2:
        return None
    dip = max(math.sqrt(float(np.mean(dip2))), DIPOLE_FLOOR * max(contrast, 0.0), 1e-9)
    return math.sqrt(float(np.mean(res2))) / dip


@pytest.mark.parametrize("seed", range(4))
def test_the_bands_fitted_in_one_batch_read_as_band_by_band(seed):
    rng = np.random.default_rng(seed)
    vals, chi, phi, rho, ok, sky = rings(bool(seed % 2), seed)
    ok[rng.choice(phi.size, 9, replace=False)] = False  # a streak's rays
    sky[:14, -20:] = False  # ground under part of the outer bands: those rays drop out there
    vals[3, 40] = np.nan  # a sample past the image circle
    got = ring_roughness(vals, chi, phi, rho, ok, sky, 180.0)
    want = _roughness_band_by_band(vals, chi, phi, rho, ok, sky, 180.0)
    assert got == pytest.approx(want, rel=1e-9)
    sky[:, 1:] = False  # one sample a ray: no band has a ray wholly on the sky
    assert ring_roughness(vals, chi, phi, rho, ok, sky, 180.0) is None


@pytest.mark.parametrize("seed", range(3))
def test_a_clouds_edge_in_the_rings_is_set_apart_and_so_is_the_ray_beyond_it(seed):
    vals, chi, phi, _, _, sky = rings(False, seed)
    assert not cloud_edges(vals, sky, phi).any()  # a clear sky's dipole and quadrupole
    vals, chi, phi, _, _, sky = rings(True, seed)
    got = cloud_edges(vals, sky, phi)
    band = (np.abs(np.degrees(phi) - 100.0) < 20.0)[:, None] & (chi[None, :] > 2.0 * RHO)
    assert (got == band).all()


def test_a_bright_edge_counts_once_the_glare_is_known_and_a_ring_with_few_rays_is_not_judged():
    vals, chi, phi, _, _, sky = rings(False, 1)
    rays = np.abs(np.degrees(phi) - 250.0) < 15.0  # a sunlit cloud's edge, or a bloom's dome
    vals[rays, 30] += 60.0  # over a ring of 73 whose dipole is 7: 40 goes unseen
    beyond = rays[:, None] & (np.arange(chi.size) >= 30)[None, :]
    assert (cloud_edges(vals, sky, phi) == beyond).all()  # the ray beyond the edge too
    assert not cloud_edges(vals, sky, phi, bright=False).any()
    sky[:37] = False  # 11 rays left on the sky: too few to tell a cloud from the sky
    assert not cloud_edges(vals - 50.0 * beyond, sky, phi).any()
