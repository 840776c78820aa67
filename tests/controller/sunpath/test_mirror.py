"""The seed method's noon from a fit balanced about noon (mirrored pairs, iterated), each
day on its own; the whole-day fit stays selectable as a labelled variant."""

import numpy as np
import pytest

from controller.sunpath.ephemeris import transit_time
from controller.sunpath.mirror import centre_candidates, mirrored_mask, nearest_centre
from controller.sunpath.parabola import fit_mirrored, fit_parabola, run_seed

from ._synth import ANDIMESHK, SANTIAGO, observations, sample_times

GRID = 8.0 + 0.25 * np.arange(35)  # the paper's February day: 08:00-16:30, every 15 min


def test_mirrored_pairs_about_a_grid_point_and_a_half_step():
    keep = mirrored_mask(GRID, 12.5)
    assert GRID[keep].min() == 8.5 and GRID[keep].max() == 16.5 and keep.sum() == 33
    keep = mirrored_mask(GRID, 12.375)  # a half-step: no sample mirrors itself
    assert keep.sum() == 34 and GRID[keep].min() == 8.25 and GRID[keep].max() == 16.5
    assert np.allclose(np.sort(GRID[keep] - 12.375), -np.sort(GRID[keep] - 12.375)[::-1])
    # a cloud hides 14:00: its mirror 11:00 leaves the set too
    gap = GRID != 14.0
    keep = mirrored_mask(GRID[gap], 12.5)
    assert keep.sum() == 31 and 11.0 not in GRID[gap][keep]
    # frame times jittered by up to 20 s still pair (tolerance 1.5 min at 15-min frames)
    jit = GRID + np.random.default_rng(1).uniform(-20, 20, GRID.size) / 3600.0
    assert mirrored_mask(jit, 12.5).sum() == 33
    assert mirrored_mask(GRID, 12.5, half_width=1.0).sum() == 9


def test_centre_is_the_grid_point_or_half_step_nearest():
    c = centre_candidates(GRID)
    assert np.allclose(np.diff(c), 0.125)  # grid points and half-steps
    assert nearest_centre(GRID, 12.43) == 12.375 and nearest_centre(GRID, 12.45) == 12.5


@pytest.mark.parametrize(
    "site,off,day,n,whole_day_at_least_s",
    [
        (ANDIMESHK, 3.5, "2024-02-12", 35, 50.0),  # 08:00-16:30 about a 12:31 noon
        (ANDIMESHK, 3.5, "2024-05-30", 36, 50.0),  # 08:00-16:45 about a 12:14 noon
        (SANTIAGO, -4.0, "2024-06-20", 36, 40.0),  # 08:00-16:45 (elevation > 3) about 12:45
    ],
)
def test_mirrored_fit_removes_the_whole_day_window_bias(site, off, day, n, whole_day_at_least_s):
    # No noise: the whole-day vertex is pulled towards the centre of an unevenly placed
    # window by tens of seconds; the balanced fit is within about ten.
    t = sample_times(day, 1, off, start_h=8.0, n_per_day=n)
    obs, az, el = observations(site, t, noise_deg=0.0)
    tt = [o.time for o in obs]
    (mir,), _ = run_seed(tt, az, el, off)
    (whole,), _ = run_seed(tt, az, el, off, fit="whole-day")
    err_m = mir.noon_utc - transit_time(mir.noon_utc, site.longitude)[0]
    err_w = whole.noon_utc - transit_time(whole.noon_utc, site.longitude)[0]
    assert abs(err_w) > whole_day_at_least_s
    assert abs(err_m) < 12.0


def test_fit_mirrored_iterates_to_a_centre_near_its_vertex():
    T = GRID
    el = 60.0 - 0.8 * (T - 12.52) ** 2 - 0.01 * (T - 12.52) ** 4  # not a parabola
    m = fit_mirrored(T, el)
    assert m is not None and m.converged and m.centre_h == 12.5
    assert nearest_centre(T, m.fit.noon_hours) == m.centre_h
    assert abs(m.fit.noon_hours - 12.52) < abs(fit_parabola(T, el).noon_hours - 12.52)
    # Only a morning: no balanced set, no noon (never a one-sided vertex passed off).
    morning = T < 11.0
    assert fit_mirrored(T[morning], el[morning]) is None


def test_each_days_noon_is_independent_of_the_previous_day():
    t = sample_times("2024-03-28", 2, 3.5, start_h=8.0, n_per_day=36)
    obs, az, el = observations(ANDIMESHK, t, noise_deg=0.3, seed=5)
    tt, az, el = np.array([o.time for o in obs]), np.asarray(az), np.asarray(el)
    day1 = tt < tt[0] + 12 * 3600
    spoilt = el.copy()
    spoilt[day1] += np.linspace(-3.0, 3.0, day1.sum())  # yesterday's data, badly wrong
    for fit in ("mirrored", "whole-day"):
        a, _ = run_seed(tt, az, el, 3.5, fit=fit)
        b, _ = run_seed(tt, az, spoilt, 3.5, fit=fit)
        assert a[1].noon_utc == b[1].noon_utc and a[0].noon_utc != b[0].noon_utc
        # the labelled chained-prior variant does carry yesterday into today
        c, _ = run_seed(tt, az, el, 3.5, fit=fit, use_prior=True)
        d, _ = run_seed(tt, az, spoilt, 3.5, fit=fit, use_prior=True)
        assert abs(c[1].noon_utc - d[1].noon_utc) > 1.0


def test_whole_day_variant_is_the_fit_of_every_sample():
    t = sample_times("2024-02-12", 1, 3.5, start_h=8.0, n_per_day=35)
    obs, az, el = observations(ANDIMESHK, t, noise_deg=0.3, seed=6)
    tt = np.array([o.time for o in obs])
    (w,), (fw,) = run_seed(tt, az, el, 3.5, fit="whole-day")
    (m,), (fm,) = run_seed(tt, az, el, 3.5)
    assert fw.n_obs == 35 and fm.n_obs == 33
    ref = fit_parabola((tt - fw.midnight) / 3600.0, el, midnight=fw.midnight)
    assert w.noon_utc == pytest.approx(ref.noon_utc, abs=1e-6)
    assert w.noon_utc != m.noon_utc
    with pytest.raises(ValueError):
        run_seed(tt, az, el, 3.5, fit="half-day")
