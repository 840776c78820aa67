import numpy as np
import pandas as pd
import pvlib
import pytest

from benchmarks.skytype import fbm
from controller.sky.fractal import fit_dimension, mean_abs_increments, scale_lags, variation_dimension


@pytest.mark.parametrize("hurst", [0.2, 0.4, 0.6, 0.8])
def test_fbm_dimension_is_two_minus_hurst(hurst):
    rng = np.random.default_rng(int(hurst * 100))
    # a day of daylight at 2 s with the paper's scales (30 .. 1050 samples)
    ds = np.array([variation_dimension(fbm(25200, hurst, rng), 2.0) for _ in range(8)])
    assert abs(ds.mean() - (2.0 - hurst)) <= 0.05
    assert np.all(np.abs(ds - (2.0 - hurst)) <= 0.12)


@pytest.mark.parametrize("hurst", [0.2, 0.8])
def test_fbm_single_realisation_at_one_minute(hurst):
    rng = np.random.default_rng(7)
    d = variation_dimension(fbm(43200, hurst, rng), 60.0)  # lags 1 .. 35 samples
    assert abs(d - (2.0 - hurst)) <= 0.05


def test_smooth_clear_sky_curve_has_dimension_one():
    loc = pvlib.location.Location(35.8, 50.95, altitude=1293)
    t = pd.date_range("2015-06-21", periods=43200, freq="2s", tz="UTC")
    g = loc.get_clearsky(t)["ghi"].to_numpy()
    assert abs(variation_dimension(g[g > 0], 2.0) - 1.0) <= 0.02
    line = np.linspace(0.0, 5.0, 5000)
    assert abs(variation_dimension(line, 60.0) - 1.0) <= 1e-9


def test_sum_over_every_pair_would_shift_the_slope_by_one():
    # guard on the normalisation: S must be the *mean* increment (dt * sum over 1/dt steps)
    rng = np.random.default_rng(1)
    y = fbm(20000, 0.5, rng)[None, :]
    lags = scale_lags(60.0)
    mean_incr = mean_abs_increments(y, np.ones_like(y, bool), lags)
    d_ok = fit_dimension(mean_incr, lags, np.array([y.size]), 60.0).D[0]
    # the slip: dt * sum over every sample instead of over the 1/dt non-overlapping steps
    summed = mean_incr * ((y.size - lags) * lags / y.size)[None, :]
    d_bad = fit_dimension(summed, lags, np.array([y.size]), 60.0).D[0]
    assert abs(d_ok - 1.5) < 0.06
    assert abs(d_ok - d_bad - 1.0) < 0.02


def test_non_overlapping_variant_agrees_on_brownian_motion():
    rng = np.random.default_rng(2)
    ds = [variation_dimension(fbm(43200, 0.5, rng), 2.0, increments="non-overlapping") for _ in range(6)]
    assert abs(np.mean(ds) - 1.5) < 0.06


def test_mean_distance_prefers_fewest_scales_slope_se_does_not():
    lags = scale_lags(60.0)
    x = np.log(lags.astype(float))
    # a gently curved log-log plot, as on station data: the literal rule takes 3 scales
    s = np.exp(0.5 * x + 0.01 * x**2)[None, :]
    lit = fit_dimension(s, lags, np.array([10_000]), 60.0, criterion="mean-distance")
    se = fit_dimension(s, lags, np.array([10_000]), 60.0, criterion="slope-se")
    assert lit.n_scales[0] == 3
    assert se.n_scales[0] > 3
    # an exactly straight plot: ties go to every scale
    straight = fit_dimension(np.exp(0.5 * x)[None, :], lags, np.array([10_000]), 60.0)
    assert straight.n_scales[0] == lags.size
    assert abs(straight.D[0] - 1.5) < 1e-9


def test_scale_break_stops_the_fit_range():
    lags = scale_lags(60.0)
    x = np.log(lags.astype(float))
    y = np.where(lags <= 10, 0.3 * x, 0.3 * np.log(10) + 1.0 * (x - np.log(10)))
    res = fit_dimension(np.exp(y)[None, :], lags, np.array([10_000]), 60.0)
    assert res.dt_max_s[0] <= 600.0
    assert abs(res.D[0] - 1.7) < 1e-6


def test_too_short_or_constant_signal_gives_nan():
    assert np.isnan(variation_dimension(np.ones(5000), 60.0))
    assert np.isnan(variation_dimension(np.arange(8.0), 60.0))
