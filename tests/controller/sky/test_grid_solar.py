import numpy as np
import pandas as pd
import pytest

from controller.sky.grid import build_day_grid, infer_step
from controller.sky.solar import cos_zenith_rows, daily_extraterrestrial_irradiation, row_geometry
from controller.sun.source import Site, solar_position


@pytest.mark.parametrize("lat,lon", [(55.79, 12.52), (-23.5, -46.6), (35.8, 50.95)])
def test_analytic_zenith_matches_spa(lat, lon):
    t0 = np.array(
        [pd.Timestamp("2016-03-10", tz="UTC").value / 1e9, pd.Timestamp("2016-07-01", tz="UTC").value / 1e9]
    )
    geo = row_geometry(t0 + 43200)
    cz = cos_zenith_rows(t0, 600, 144, lat, lon, geo)
    t = (t0[:, None] + np.arange(144) * 600).ravel()
    spa = solar_position(Site(lat, lon), t)["zenith"].to_numpy()  # geometric, no refraction
    # declination held at its noon value over the day: <= 0.5 deg near the equinox
    assert np.max(np.abs(cz.ravel() - np.cos(np.radians(spa)))) < 0.008


def test_daily_h0_matches_numeric_integral():
    lat = 48.0
    t0 = np.array([pd.Timestamp("2016-06-21", tz="UTC").value / 1e9])
    geo = row_geometry(t0 + 43200)
    cz = cos_zenith_rows(t0, 10, 8640, lat, 0.0, geo)
    numeric = 10 * geo["e0"][0] * np.sum(np.maximum(cz, 0))
    h0 = daily_extraterrestrial_irradiation(lat, geo["declination"], geo["e0"])[0]
    assert abs(numeric / h0 - 1) < 1e-3
    assert 41e6 < h0 < 43e6  # Duffie & Beckman: about 41.7-42 MJ/m2 at 48 N in June


@pytest.mark.parametrize("step", [1, 2, 10, 30, 60])
def test_infer_step(step):
    t = 1.45e9 + np.arange(2000) * step
    assert infer_step(t) == step
    jitter = t + np.random.default_rng(0).uniform(-0.2, 0.2, t.size)
    assert infer_step(jitter) == step


def test_coarser_than_a_minute_is_refused():
    with pytest.raises(ValueError, match="coarser than 60 s"):
        infer_step(1.45e9 + np.arange(100) * 300.0)


def test_shuffled_duplicated_jittered_samples_bin_like_clean_ones():
    rng = np.random.default_rng(1)
    t = 1.45e9 + np.arange(3 * 1440) * 60.0
    g = rng.uniform(0, 800, t.size)
    clean = build_day_grid(t, g, 10.0)
    dup = np.concatenate([np.arange(t.size), rng.choice(t.size, 500)])  # duplicates
    order = rng.permutation(dup.size)
    messy = build_day_grid(t[dup][order] + rng.uniform(-5, 5, dup.size), g[dup][order], 10.0, step_s=60)
    assert np.array_equal(clean.day_index, messy.day_index)
    np.testing.assert_allclose(np.nan_to_num(messy.ghi), np.nan_to_num(clean.ghi), rtol=1e-6)
    assert messy.n_samples.sum() == t.size + 500


def test_solar_day_keeps_an_american_afternoon_together():
    # at 105 W solar noon is about 19 UTC; the UTC date changes mid-afternoon
    t = pd.Timestamp("2016-06-01T12:00Z").value / 1e9 + np.arange(0, 12 * 3600, 60.0)
    grid = build_day_grid(t, np.ones(t.size), -105.0)
    assert grid.day_index.size == 1
    assert str(grid.dates[0]) == "2016-06-01"


@pytest.mark.parametrize("spacing,step", [(11.0, 12), (7.0, 8), (59.5, 60), (2.0, 2), (1.0, 1)])
def test_odd_sampling_leaves_no_empty_slot(spacing, step):
    t = 1.45e9 + np.arange(0.0, 86400.0 * 2, spacing)
    assert infer_step(t) == step
    grid = build_day_grid(t, np.ones(t.size), 0.0)
    inner = grid.ghi[:, 10:-10]  # the ends of the record are partial days
    assert np.isfinite(inner[grid.n_samples > 0.9 * grid.n_samples.max()]).all()


def test_step_of_a_large_shuffled_record():
    t = 1.45e9 + np.arange(400_000) * 2.0
    np.random.default_rng(4).shuffle(t)
    assert infer_step(t) == 2
