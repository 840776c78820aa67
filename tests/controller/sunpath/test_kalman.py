import numpy as np
import pytest

from controller.sun.types import SunObservation, angle_between_deg, azel_to_enu
from controller.sunpath.batch import run_kalman
from controller.sunpath.ephemeris import geocentric_sun, transit_time, wrap180
from controller.sunpath.kalman import KalmanConfig, SunPathKalman

from ._synth import ANDIMESHK, SANTIAGO, observations, sample_times

CASES = [(ANDIMESHK, 3.5), (SANTIAGO, -4.0)]


@pytest.fixture(scope="module", params=CASES, ids=["north", "south"])
def learnt(request):
    site, off = request.param
    t = sample_times("2024-04-10", 4, off)
    obs, _, _ = observations(site, t, az_offset_deg=20.0, seed=11)
    rows, kf = run_kalman(obs, KalmanConfig(declination="free"), utc_offset_h=off)
    return site, rows, kf


def test_self_localisation_both_hemispheres(learnt):
    site, rows, kf = learnt
    assert kf.mode == "free" and len(rows) == 4
    last = rows[-1]
    assert abs(last.lat_deg - site.latitude) < 0.2
    assert abs(wrap180(last.lon_deg - site.longitude)) < 0.1
    assert abs(wrap180(last.az_offset_deg - 20.0)) < 0.2
    tr = transit_time(last.noon_utc, site.longitude)[0]
    assert abs(last.noon_utc - tr) < 20.0
    assert abs(last.declination_deg - geocentric_sun(tr).dec_deg[0]) < 0.2
    assert last.lat_sigma_deg < rows[0].lat_sigma_deg  # it keeps learning across nights


def test_prediction_across_gap_and_covariance(learnt):
    site, rows, kf = learnt
    from controller.sun.source import solar_position

    t = rows[-1].noon_utc + 86400.0 + np.array([-7200.0, 0.0, 3600.0])
    sp = solar_position(site, t)
    preds = [kf.predict(x) for x in t]
    a = np.array([p.az_deg for p in preds])
    e = np.array([p.el_deg for p in preds])
    err = angle_between_deg(azel_to_enu(a, e), azel_to_enu(sp["azimuth"], sp["apparent_elevation"]))
    assert err.max() < 0.3
    for p in preds:
        assert np.all(np.linalg.eigvalsh(p.covariance) > 0)
    # Process noise widens the covariance across nights (site, azimuth offset); the
    # direction's sigma need not grow: the orbit maps a longitude error onto declination
    # less and less as the sun nears a solstice.
    _, P_far = kf._propagated(kf.t + 20 * 86400.0)
    assert np.all(np.diag(P_far)[[0, 1, 4, 5]] > np.diag(kf.P)[[0, 1, 4, 5]])
    assert kf.predict(kf.t + 20 * 86400.0).sigma_deg < 0.3


def test_outliers_are_gated(learnt):
    _site, _rows, kf = learnt
    kf = kf.copy()
    t = kf.t + 900.0
    x0, _ = kf._propagated(t)  # the time update happens whatever the observation
    p = kf.predict(t)
    bad = SunObservation(t, (p.az_deg + 20.0 + 5.0) % 360.0, p.el_deg - 5.0, 0.3)
    res = kf.update(bad)
    assert not res.accepted and res.mahalanobis2 > kf.config.gate_chi2
    assert np.allclose(kf.x, x0)
    good = SunObservation(t + 60, (kf.predict(t + 60).az_deg + 20.0) % 360, kf.predict(t + 60).el_deg, 0.3)
    assert kf.update(good).accepted


def test_known_site_starts_at_once_and_learns_offset():
    t = sample_times("2024-06-01", 1, 3.5)
    obs, _, _ = observations(ANDIMESHK, t, az_offset_deg=243.926, seed=5)
    kf = SunPathKalman(KalmanConfig(declination="ephemeris"), site=ANDIMESHK)
    assert kf.mode == "ephemeris"
    assert kf.update(obs[0]).initialised
    for o in obs[1:]:
        kf.update(o)
    assert abs(wrap180(kf.x[4] - 243.926)) < 0.1
    assert abs(kf.x[0] - ANDIMESHK.latitude) < 0.05


def test_unstarted_filter_cannot_predict_and_state_round_trips(learnt):
    with pytest.raises(RuntimeError):
        SunPathKalman().predict(0.0)
    _, _, kf = learnt
    kf2 = SunPathKalman.from_dict(kf.to_dict())
    t = kf.t + 3600.0
    assert kf2.predict(t).az_deg == pytest.approx(kf.predict(t).az_deg, abs=1e-9)
    assert np.allclose(kf2.P, kf.P)


def test_the_jacobian_does_not_straddle_the_refraction_step():
    """An audit's case: SPA's refraction steps by 0.616 deg at true elevation -0.833 deg; a
    central difference across it made d(el)/d(lat) about 3000 and the update collapsed the
    latitude's sigma.  The slope is now the geometry's (about 1 there)."""
    from scipy.optimize import brentq

    from controller.sun.source import Site
    from controller.sunpath.ephemeris import azel_from_hour_angle
    from controller.sunpath.kalman import LAT

    switch = -(0.26667 + 0.5667)  # SPA: no refraction below this true elevation

    kf = SunPathKalman(KalmanConfig(), site=Site(69.6, 18.9))
    t = 1737194400.0  # 2025-01-18 10:00 UTC, the polar-winter sun near the horizon
    geo = geocentric_sun(t)
    h = geo.hour_angle_deg(18.9)

    def el0(lat):  # true (airless) elevation
        return float(azel_from_hour_angle(h, geo.dec_deg, lat, 0.0)[1][0]) - switch

    x = np.array([brentq(el0, 60.0, 75.0) + 2e-5, 18.9, 0.0, 0.0, 0.0, 1.0])
    J = kf._jacobian(x, geo)
    assert 0.5 < abs(J[1, LAT]) < 2.0, J
