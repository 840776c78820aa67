import numpy as np
import pytest

from controller.sunpath.ephemeris import transit_time
from controller.sunpath.parabola import azimuth_offset_at_culmination, fit_parabola, run_seed

from ._synth import ANDIMESHK, SANTIAGO, observations, sample_times


def test_exact_parabola_recovered():
    T = np.linspace(8, 17, 20)
    el = 60.0 - 0.8 * (T - 12.3) ** 2
    fit = fit_parabola(T, el, midnight=1000.0)
    assert fit.noon_hours == pytest.approx(12.3, abs=1e-9)
    assert fit.noon_el_deg == pytest.approx(60.0, abs=1e-9)
    assert fit.noon_utc == pytest.approx(1000.0 + 12.3 * 3600)
    assert fit.variance < 1e-18


def test_variance_factor_estimates_noise():
    rng = np.random.default_rng(3)
    T = np.linspace(8, 17, 400)
    el = 60.0 - 0.8 * (T - 12.3) ** 2 + rng.normal(0, 0.3, T.size)
    fit = fit_parabola(T, el)
    assert np.sqrt(fit.variance) == pytest.approx(0.3, rel=0.15)
    assert fit.noon_sigma_s > 0


def test_prior_makes_one_observation_enough():
    rng = np.random.default_rng(4)
    T = np.linspace(8, 17, 35)
    yesterday = fit_parabola(T, 60.0 - 0.8 * (T - 12.3) ** 2 + rng.normal(0, 0.3, T.size))
    today = fit_parabola([8.0], [60.1 - 0.8 * (8.0 - 12.3) ** 2], prior=yesterday)
    assert today.used_prior
    assert abs(today.noon_hours - 12.3) < 0.05
    with pytest.raises(ValueError):
        fit_parabola([8.0, 9.0], [1.0, 2.0])


@pytest.mark.parametrize("site,offset,side", [(ANDIMESHK, 243.926, "south"),
                                             (SANTIAGO, 10.0, "north")])
def test_azimuth_alignment_at_culmination(site, offset, side):
    t = sample_times("2024-03-20", 1, 3.5 if site is ANDIMESHK else -4.0)
    obs, _, _ = observations(site, t, noise_deg=0.05, az_offset_deg=offset, seed=1)
    got = azimuth_offset_at_culmination([o.az_deg for o in obs], [o.el_deg for o in obs], side)
    assert abs(((got - offset + 180) % 360) - 180) < 0.5


@pytest.mark.parametrize("site,off", [(ANDIMESHK, 3.5), (SANTIAGO, -4.0)])
def test_seed_noon_windowed_near_transit(site, off):
    # Noise-free, +-1.5 h window: the parabola extremum is near the true transit and the
    # localisation formulas recover the site to within the model error of a parabola.
    t = sample_times("2024-04-01", 2, off)
    obs, az, el = observations(site, t, noise_deg=0.0)
    rows, fits = run_seed([o.time for o in obs], az, el, off, lat_deg=site.latitude,
                          window_h=1.5)
    assert len(rows) == 2 and fits[1].used_prior
    for r in rows:
        tr = transit_time(r.noon_utc, site.longitude)[0]
        assert abs(r.noon_utc - tr) < 60.0
        assert abs(r.lat_deg - site.latitude) < 0.6
        assert abs(r.lon_deg - site.longitude) < 0.3
