"""Sky-only declination: the orbit law bridges multi-week breaks, and no SPA declination
value is used in ``free`` mode."""

import numpy as np
import pandas as pd
import pytest

from controller.sunpath import initial_fit, kalman
from controller.sunpath.batch import run_kalman
from controller.sunpath.ephemeris import GeocentricSun, geocentric_sun
from controller.sunpath.kalman import DEC, RATE, KalmanConfig, SunPathKalman, orbit_advance_deg

from ._synth import ANDIMESHK, SANTIAGO, observations, sample_times


def _ts(day: str) -> float:
    return pd.Timestamp(day, tz="UTC").timestamp()


def test_orbit_advance_kepler_rate():
    year = 365.2422 * 86400.0
    t0 = _ts("2024-01-01")
    for rate in ("kepler", "mean"):
        assert float(orbit_advance_deg(t0, t0 + year, rate)) == pytest.approx(360.0, abs=0.01)
    # Faster near perihelion (early January) than near aphelion (early July).
    jan = float(orbit_advance_deg(_ts("2024-01-03"), _ts("2024-01-04")))
    jul = float(orbit_advance_deg(_ts("2024-07-04"), _ts("2024-07-05")))
    assert jan == pytest.approx(1.019, abs=0.002) and jul == pytest.approx(0.953, abs=0.002)

    # Against SPA's apparent longitude (via its declination and RA) over a 34-day break.
    def lam(t):
        g = geocentric_sun(t)
        return (
            np.degrees(
                np.arctan2(
                    np.sin(np.radians(g.ra_deg)), np.cos(np.radians(g.ra_deg)) * np.cos(np.radians(23.4393))
                )
            )[0]
            % 360.0
        )

    a, b = _ts("2024-02-22T09:00"), _ts("2024-03-27T09:00")
    true_adv = (lam(b) - lam(a)) % 360.0
    assert float(orbit_advance_deg(a, b)) == pytest.approx(true_adv, abs=0.01)
    assert abs(float(orbit_advance_deg(a, b, "mean")) - true_adv) > 0.1  # why Kepler


@pytest.fixture(scope="module", params=[(ANDIMESHK, 3.5), (SANTIAGO, -4.0)], ids=["north", "south"])
def february(request):
    """Three February days, site unknown, sky-only declination."""
    site, off = request.param
    t = np.concatenate(
        [
            sample_times("2024-02-12", 2, off, start_h=8.0, n_per_day=35),
            sample_times("2024-02-21", 2, off, start_h=8.0, n_per_day=35),
        ]
    )
    obs, _, _ = observations(site, t, seed=3)
    rows, kf = run_kalman(obs, KalmanConfig(declination="free"), utc_offset_h=off)
    return site, off, rows, kf


def test_declination_bridged_across_a_five_week_break(february):
    _site, off, _rows, kf = february
    assert kf.mode == "free" and kf.obliquity_applied
    assert kf.obliquity_deg() == pytest.approx(23.44, abs=0.05)
    for day in ("2024-02-23", "2024-03-27", "2024-04-30"):  # 1, 34 and 68 days on
        t = _ts(day) - off * 3600 + 12.3 * 3600
        dec, sig = kf.declination(t)
        err = dec - geocentric_sun(t).dec_deg[0]
        assert abs(err) < 0.1, (day, err)
        assert abs(err) < 4 * sig + 0.02
    # The filter's own rate (from u, v): about +0.37 deg/day in late February.
    x = kf.x
    rate = np.degrees(x[RATE] * np.radians(0.9856)) / np.cos(np.arcsin(x[DEC]))
    assert rate == pytest.approx(0.37, abs=0.03)


def test_free_mode_never_reads_spa_declination(monkeypatch):
    """Replace SPA's declination by garbage: the sky-only filter must not change."""
    site, off = ANDIMESHK, 3.5
    t = sample_times("2024-03-28", 1, off, start_h=8.0, n_per_day=36)
    obs, _, _ = observations(site, t, seed=9)
    rows_a, kf_a = run_kalman(obs, KalmanConfig(declination="free"), utc_offset_h=off)

    def poisoned(tt):
        g = geocentric_sun(tt)
        return GeocentricSun(g.sidereal_deg, g.ra_deg, g.dec_deg + 7.0)

    monkeypatch.setattr(kalman, "geocentric_sun", poisoned)  # the EKF's updates
    monkeypatch.setattr(initial_fit, "geocentric_sun", poisoned)  # and its start
    rows_b, kf_b = run_kalman(obs, KalmanConfig(declination="free"), utc_offset_h=off)
    assert [r.declination_deg for r in rows_a] == pytest.approx(
        [r.declination_deg for r in rows_b], abs=1e-12
    )
    assert np.allclose(kf_a.x, kf_b.x, atol=1e-12)
    # ... whereas the ephemeris mode does read it.
    rows_c, _ = run_kalman(obs, KalmanConfig(declination="ephemeris"), utc_offset_h=off)
    assert abs(rows_c[-1].lat_deg - rows_a[-1].lat_deg) > 0.3


def test_old_free_state_file_is_converted(february):
    _site, _off, _rows, kf = february
    d = kf.to_dict()
    dec, _sig = kf.declination(kf.t)
    # An old-format state: declination (deg) and rate (deg/day), no "free_model" tag.
    old = dict(d)
    old.pop("free_model")
    u, v = kf.x[DEC], kf.x[RATE]
    rate = np.degrees(v * np.radians(kalman.MEAN_MOTION_DEG_PER_DAY)) / np.cos(np.arcsin(u))
    x = list(d["x"])
    x[DEC], x[RATE] = float(np.degrees(np.arcsin(u))), float(rate)
    old["x"] = x
    P = np.array(d["P"])
    P[DEC, :] = P[:, DEC] = P[RATE, :] = P[:, RATE] = 0.0
    P[DEC, DEC], P[RATE, RATE] = 0.05**2, 0.01**2
    old["P"] = P.tolist()
    kf2 = SunPathKalman.from_dict(old)
    dec2, _ = kf2.declination(kf2.t)
    assert dec2 == pytest.approx(dec, abs=1e-9)
    assert kf2.x[RATE] == pytest.approx(v, rel=1e-9)
