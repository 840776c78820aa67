"""The sky behind the glare (skybg): the elevation model near the horizon."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.vision.fisheye.skybg import sky_by_elevation

RHO = 0.1  # the rim's radius (rad)


def rings(cloud: bool, seed: int) -> tuple[np.ndarray, ...]:
    """Rings 1.15-3.2 rim radii out around a glare 2 radii above the horizon: the glare's
    profile, a sky brightening towards the horizon (``-6 x + x^2`` grey levels, ``x`` the
    elevation offset over the radius), noise; with ``cloud``, a dark band 60 grey levels
    deep over a 100 deg sector of the rings beyond 2 radii."""
    rng = np.random.default_rng(seed)
    phi = np.arange(40) * (2 * math.pi / 40)
    chi = np.arange(1.15 * RHO, 3.2 * RHO, 0.02 * RHO)
    x = (chi[None, :] / RHO) * np.cos(phi)[:, None]
    glare = 80.0 + 90.0 * np.exp(-(chi - RHO) / (0.3 * RHO))
    vals = glare[None, :] - 6.0 * x + x**2 + rng.normal(0.0, 0.5, x.shape)
    if cloud:
        band = (np.abs(np.degrees(phi)[:, None] - 60.0) < 50.0) & (chi[None, :] > 2.0 * RHO)
        vals = np.where(band, vals - 60.0, vals)
    return vals, chi, phi, x > -2.0, x


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("cloud", [False, True], ids=["clear", "cloud band in the outer rings"])
def test_the_horizons_brightening_at_the_rim_is_read_through_a_cloud_in_the_outer_rings(cloud, seed):
    # with two rounds of clipping the band, still half in the fit, left the rim's model 6-8
    # grey levels off (the brightening read 0.6 and 3.3 at x = -1 and +1 for 7 and -5)
    vals, chi, phi, sky, x = rings(cloud, seed)
    c = sky_by_elevation(vals, chi, phi, RHO, np.ones(phi.size, bool), sky, x, 175.0)
    assert c is not None
    at_rim = np.polyval([c[2], c[1], c[0], 0.0], np.array([-1.0, 1.0]))
    np.testing.assert_allclose(at_rim, [7.0, -5.0], atol=1.0)


def test_rings_with_gaps_and_outliers_get_each_rings_own_robust_fit():
    """The rings that need clipping are fitted in one batch; each gets what the ring's own
    robust fit gives: gaps, a streak's outliers, a cloud's edge, rays clipped on one
    round and taken back on the next, a ring left with too few rays (no dipole)."""
    from controller.vision.fisheye.skybg import harmonic, harmonics

    rng = np.random.default_rng(11)
    phi = np.arange(36) * (2 * np.pi / 36)
    M = 40 + 3 * np.cos(phi - 0.4) + 0.6 * np.cos(2 * phi) + rng.normal(0, 0.4, (300, 36))
    for row in M:
        k = rng.integers(0, 36)
        n = rng.integers(1, 14)
        row[(k + np.arange(n)) % 36] += rng.choice([-1, 1]) * rng.uniform(2, 60)  # a streak, a cloud
        row[rng.random(36) < rng.uniform(0, 0.7)] = np.nan  # gaps; some rings left too few
    got = harmonics(phi, M)
    want = np.array([harmonic(phi, m) for m in M])
    assert np.allclose(got, want, rtol=0, atol=1e-9)
    assert (want == 0).all(axis=1).sum() >= 10  # rings without a dipole were met


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_skys_dipole_at_the_rim_is_read_from_the_rings_that_count(dtype):
    """A sky ``(0.8 chi / rho + 0.4 (chi / rho)^2) cos(phi - 0.7)`` around a glare's profile:
    the dipole at the rim is 1.2 grey levels towards 0.7 rad, read from the rings outside;
    rays left out by design and a ring cut short by the horizon do not change it, and fewer
    than four rings give none."""
    from controller.vision.fisheye.skybg import sky_dipole

    rng = np.random.default_rng(2)
    phi = np.arange(36) * (2 * np.pi / 36)
    chi = np.arange(1.15 * RHO, 3.2 * RHO + 0.16 * RHO, 0.12 * RHO)
    s = chi / RHO
    glare = 60.0 + 150.0 * np.exp(-(chi - RHO) / (0.3 * RHO))
    vals = (
        glare + np.outer(np.cos(phi - 0.7), 0.8 * s + 0.4 * s**2) + rng.normal(0, 0.05, (36, s.size))
    ).astype(dtype)
    ok = np.ones(36, bool)
    want = 1.2 * np.array([np.cos(0.7), np.sin(0.7)])
    np.testing.assert_allclose(sky_dipole(vals, chi, phi, RHO, ok, 200.0), want, atol=0.05)
    ok[np.sin(phi) >= np.sin(np.radians(50))] = False  # the rays towards a one-way streak: 22 %
    np.testing.assert_allclose(sky_dipole(vals, chi, phi, RHO, ok, 200.0), want, atol=0.05)
    sky = np.ones(vals.shape, bool)
    sky[:20, s > 2.8] = False  # the outermost ring mostly below the horizon: dropped
    np.testing.assert_allclose(sky_dipole(vals, chi, phi, RHO, ok, 200.0, sky), want, atol=0.05)
    sky[:20, s > 2.0] = False  # three rings left: no dipole
    assert sky_dipole(vals, chi, phi, RHO, ok, 200.0, sky).tolist() == [0.0, 0.0]


def _by_elevation_ring_by_ring(vals, chi, phi, rho, good, x):
    """The elevation model's design, built ring by ring (the reference)."""
    from controller.vision.fisheye.skybg import RING_EDGES
    from controller.vision.fisheye.small import gradient

    prof = np.nanmean(np.where(good, vals, np.nan), axis=0)
    dprof = gradient(prof, chi)
    edges = RING_EDGES
    rows, rhs = [], []
    for j, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        sel = (chi >= lo * rho) & (chi < hi * rho)
        ok = good[:, sel].all(axis=1)
        if sel.sum() < 2 or ok.sum() < 6:
            continue
        xx = x[ok][:, sel].mean(axis=1)
        dp, sj = float(dprof[sel].mean()), float(chi[sel].mean()) / rho - 1.0
        one = np.zeros((ok.sum(), len(edges) - 1))
        one[:, j] = 1.0
        rows.append(
            np.column_stack([one, -dp * np.cos(phi[ok]), -dp * np.sin(phi[ok]), xx, xx**2, xx**3, xx * sj])
        )
        rhs.append(vals[ok][:, sel].mean(axis=1))
    A = np.concatenate(rows)
    A = np.concatenate(
        [A[:, np.flatnonzero(A[:, : len(edges) - 1].any(axis=0))], A[:, len(edges) - 1 :]], axis=1
    )
    return A, np.concatenate(rhs)


@pytest.mark.parametrize("seed", range(4))
def test_the_elevation_models_rings_are_read_as_ring_by_ring(seed, monkeypatch):
    """All rings reduced at once give the design a ring-by-ring reading gives, rings left out
    (too few rays wholly on the sky) included."""
    from controller.vision.fisheye import skybg

    vals, chi, phi, sky, x = rings(bool(seed % 2), seed)
    rng = np.random.default_rng(seed)
    sky = sky & (rng.random(sky.shape) > 0.01)  # scattered samples off the sky
    sky[:, (chi > 1.4 * RHO) & (chi < 1.7 * RHO)] &= phi[:, None] < 0.5  # a ring with too few rays
    seen = []
    real = np.linalg.lstsq
    monkeypatch.setattr(
        skybg.np.linalg, "lstsq", lambda A, b, rcond=None: seen.append((A, b)) or real(A, b, rcond=rcond)
    )
    assert skybg.sky_by_elevation(vals, chi, phi, RHO, np.ones(phi.size, bool), sky, x, 175.0) is not None
    A, b = _by_elevation_ring_by_ring(vals, chi, phi, RHO, sky, x)
    assert seen[0][0].shape == A.shape and A.shape[1] == 5 + 6  # one ring dropped
    np.testing.assert_allclose(seen[0][0], A, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(seen[0][1], b, rtol=1e-12, atol=1e-9)
