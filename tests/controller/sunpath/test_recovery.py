"""The filter never leaves physical bounds and recovers from inconsistent data (issue 13,
item 8): a one-hour step back in the observation times, observations older than the
state, garbage, a clock that stepped back for good, a sensor knocked round."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controller.sun.types import SunObservation
from controller.sunpath.bounds import max_sigma
from controller.sunpath.ephemeris import wrap180
from controller.sunpath.kalman import KalmanConfig, SunPathKalman
from controller.sunpath.kalman_config import AZOFF, LAT, LON
from controller.sunpath.policy import SunPathSource

from ._synth import ANDIMESHK, observations, sample_times

TRUTH = ANDIMESHK


def assert_physical(kf: SunPathKalman) -> None:
    """The invariant: a finite state inside its bounds, a covariance that means something."""
    if not kf.initialised:
        return
    x, P = np.asarray(kf.x, float), np.asarray(kf.P, float)
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(P))
    assert -90.0 <= x[LAT] <= 90.0 and -180.0 <= x[LON] <= 180.0
    assert np.allclose(P, P.T, atol=1e-12 * np.abs(P).max())
    assert np.linalg.eigvalsh(P).min() >= -1e-9 * np.abs(np.diag(P)).max()
    assert np.all(np.diag(P) <= max_sigma(kf.mode) ** 2)


# ---------------------------------------------------------------- the repro (issue 13)
TIMES = sample_times("2024-03-01", 8, 3.5, n_per_day=35)
OBS, _, _ = observations(TRUTH, TIMES, 0.3, seed=2)


def stepped_back(k: int, order: str) -> list[SunObservation]:
    """Every observation from index ``k`` on labelled one hour early (a wall-clock step).

    ``sorted``: as ``read_observations`` gives them; ``camera``: in the order taken, so the
    times go back by an hour at ``k``.
    """
    out = [
        SunObservation(o.time - 3600.0, o.az_deg, o.el_deg, o.sigma_deg) if i >= k else o
        for i, o in enumerate(OBS)
    ]
    return sorted(out, key=lambda o: o.time) if order == "sorted" else out


def feed(src: SunPathSource, obs) -> None:
    for o in obs:
        src.observe(o)
        assert_physical(src.kf)


# k = 18: before the filter starts (site unknown); k = 133: day 4, where the unbounded
# inflation took the latitude to 412 deg in free mode.
@pytest.mark.parametrize("k", [18, 133])
@pytest.mark.parametrize("mode", ["free", "ephemeris"])
def test_one_hour_step_back_site_unknown_follows_the_consistent_shift(k, mode):
    src = SunPathSource(kalman_config=KalmanConfig(declination=mode))
    feed(src, stepped_back(k, "sorted"))
    s = src.summary()
    assert abs(s["lat_deg"] - TRUTH.latitude) < 1.0
    # From the sky alone a clock an hour early is a site 15 deg east: the sun stands where
    # the labels say it should one hour later, i.e. 15 deg of hour angle further on.
    assert abs(wrap180(s["lon_deg"] - TRUTH.longitude) - 15.0) < 0.5
    assert s["reinitialised"] >= 1


@pytest.mark.parametrize("k", [18, 133])
@pytest.mark.parametrize("mode", ["free", "ephemeris"])
def test_one_hour_step_back_site_known_keeps_the_site_and_reports_it(k, mode):
    src = SunPathSource(TRUTH, kalman_config=KalmanConfig(declination=mode))
    feed(src, stepped_back(k, "sorted")[:175])  # five days: the verdict comes on day 5
    s = src.summary()
    assert abs(s["site_offset_lat_deg"]) < 0.05 and abs(s["site_offset_lon_deg"]) < 0.05
    assert s["site_mismatch"] is True
    assert abs(s["site_mismatch_lon_deg"] - 15.0) < 0.5
    assert abs(s["site_mismatch_lat_deg"]) < 1.0
    # the loop's SUN ALARM names the likely mistake: stamps an hour off UTC
    assert "time stamps' zone" in s["site_mismatch_cause"] and "-1 h" in s["site_mismatch_cause"]


@pytest.mark.parametrize("known", [False, True], ids=["site-unknown", "site-known"])
def test_one_hour_step_back_in_camera_order(known):
    # The loop feeds frames in the order taken: after the step the first frames are older
    # than the state.  They are rejected and counted; the filter goes on as above.
    src = SunPathSource(TRUTH if known else None, kalman_config=KalmanConfig(declination="free"))
    feed(src, stepped_back(133, "camera")[:175])
    s = src.summary()
    assert s["older"] == 3  # the hour taken twice, but for the frame at the state's own time
    assert abs(s["lat_deg"] - TRUTH.latitude) < 1.0
    expected_lon = 0.0 if known else 15.0
    assert abs(wrap180(s["lon_deg"] - TRUTH.longitude) - expected_lon) < 0.5
    assert s.get("site_mismatch", False) is known


def test_clean_data_is_untouched_by_the_recovery_rules():
    src = SunPathSource(kalman_config=KalmanConfig(declination="free"))
    feed(src, OBS)
    s = src.summary()
    assert s["reinitialised"] == 0 and s["older"] == 0 and s["invalid"] == 0
    assert abs(s["lat_deg"] - TRUTH.latitude) < 0.2
    assert abs(wrap180(s["lon_deg"] - TRUTH.longitude)) < 0.1


# ---------------------------------------------------------------- single observations
@pytest.fixture(scope="module", params=["free", "ephemeris"])
def learnt(request):
    obs, _, _ = observations(TRUTH, sample_times("2024-04-10", 2, 3.5), seed=4)
    kf = SunPathKalman(KalmanConfig(declination=request.param))
    for o in obs:
        kf.update(o)
    assert kf.initialised
    return kf


def test_an_observation_older_than_the_state_is_rejected_and_counted(learnt):
    kf = learnt.copy()
    x0, rej0 = kf.x.copy(), kf.n_rejected
    res = kf.update(SunObservation(kf.t - 600.0, 180.0, 40.0, 0.3))
    assert not res.accepted and res.reason == "older than the state"
    assert np.array_equal(kf.x, x0)
    assert kf.n_rejected == rej0 + 1 and kf.n_older == 1


@pytest.mark.parametrize(
    "az, el, sigma, dt",
    [
        (float("nan"), 40.0, 0.3, 600.0),
        (180.0, float("inf"), 0.3, 600.0),
        (180.0, 120.0, 0.3, 600.0),
        (180.0, 40.0, 0.0, 600.0),
        (180.0, 40.0, -1.0, 600.0),
        (180.0, 40.0, float("nan"), 600.0),
    ],
)
def test_an_invalid_observation_never_reaches_the_state(learnt, az, el, sigma, dt):
    kf = learnt.copy()
    x0, P0 = kf.x.copy(), kf.P.copy()
    res = kf.update(SunObservation(kf.t + dt, az, el, sigma))
    assert np.array_equal(kf.x, x0) and np.array_equal(kf.P, P0)
    assert not res.accepted and res.reason.startswith("invalid observation")
    assert kf.n_invalid == 1


def garbage(t0: float, n: int, seed: int, step_s: float = 900.0) -> list[SunObservation]:
    rng = np.random.default_rng(seed)
    return [
        SunObservation(t0 + step_s * (i + 1), float(rng.uniform(0, 360)), float(rng.uniform(5, 85)), 0.3)
        for i in range(n)
    ]


def test_a_long_run_of_garbage_neither_moves_nor_blows_up_the_state(learnt):
    kf = learnt.copy()
    lat0 = kf.x[LAT]
    for o in garbage(kf.t, 80, seed=1):
        kf.update(o)
        assert_physical(kf)
    # widened once and boundedly (process noise aside), never a restart on garbage, and
    # garbage never let in
    cap = kf.config.max_inflation_sigma_deg * 1.001
    assert kf.sigma(LAT) <= cap and kf.sigma(LON) <= cap
    assert kf.n_reinit == 0 and kf.n_accepted == learnt.n_accepted
    assert kf.x[LAT] == lat0


@settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    seq=st.lists(
        st.tuples(
            st.floats(-1800.0, 3600.0),
            st.floats(-720.0, 720.0),
            st.floats(-100.0, 100.0),
            st.floats(1e-3, 20.0),
            st.sampled_from([False] * 9 + [True]),
        ),
        min_size=20,
        max_size=60,
    )
)
def test_random_observations_never_leave_physical_bounds(learnt, seq):
    # Garbage: times that step forwards and backwards, directions anywhere (some not even
    # on the sky), sigmas from 0.001 to 20 deg, a true observation now and then.
    kf = learnt.copy()
    t = kf.t
    for dt, az, el, sigma, true_sun in seq:
        t += dt
        if true_sun:
            p = learnt.predict(t)
            az, el = p.az_deg + learnt.x[AZOFF], p.el_deg
        kf.update(SunObservation(t, az, el, sigma))
        assert_physical(kf)


# ---------------------------------------------------------------- clock, sensor
@pytest.mark.parametrize("mode", ["free", "ephemeris"])
def test_a_clock_that_stepped_back_for_good_does_not_wedge_the_filter(mode):
    # The clock ran a year ahead for two days (the filter learned with those labels), then
    # NTP put it right.  Every later observation is a year older than the state: before,
    # all were rejected for a year.  Now the state is carried back to them.
    year = 365 * 86400.0
    t = sample_times("2024-04-10", 4, 3.5)
    obs, _, _ = observations(TRUTH, t, seed=6)
    ahead = [SunObservation(o.time + year, o.az_deg, o.el_deg, o.sigma_deg) for o in obs]
    n_ahead = sum(o.time < t[0] + 2 * 86400 for o in obs)
    kf = SunPathKalman(KalmanConfig(declination=mode), TRUTH)
    for o in ahead[:n_ahead]:
        kf.update(o)
    acc0 = kf.n_accepted
    for o in obs[n_ahead:]:
        kf.update(o)
        assert_physical(kf)
    after = len(obs) - n_ahead
    assert kf.n_accepted - acc0 >= 0.8 * after
    assert kf.t == obs[-1].time
    assert abs(kf.x[LAT] - TRUTH.latitude) < 0.2
    assert kf.n_rebase == 1 and kf.n_older == kf.config.max_consecutive_older


def test_a_sensor_knocked_round_in_azimuth_is_relearnt_with_the_site_kept():
    t = sample_times("2024-04-10", 3, 3.5)
    obs, _, _ = observations(TRUTH, t, az_offset_deg=5.0, seed=7)
    knock = t[0] + 86400 * 1.2
    obs = [
        SunObservation(o.time, (o.az_deg + 12.0) % 360 if o.time > knock else o.az_deg, o.el_deg, o.sigma_deg)
        for o in obs
    ]
    kf = SunPathKalman(KalmanConfig(), TRUTH)
    for o in obs:
        kf.update(o)
        assert_physical(kf)
    assert abs(wrap180(kf.x[AZOFF] - 17.0)) < 0.2
    assert abs(kf.x[LAT] - TRUTH.latitude) < 0.05
    assert abs(wrap180(kf.x[LON] - TRUTH.longitude)) < 0.05


def test_a_state_from_the_future_that_slipped_in_is_rebased():
    # Belt and braces: even a filter whose time is far ahead (a state file saved under a
    # wrong clock and loaded without "now") does not stay locked out.
    t = sample_times("2024-04-10", 2, 3.5)
    obs, _, _ = observations(TRUTH, t, seed=8)
    kf = SunPathKalman(KalmanConfig(), TRUTH)
    for o in obs[:10]:
        kf.update(o)
    kf._propagate(pd.Timestamp("2030-01-01T00:00:00Z").timestamp())
    for o in obs[10:]:
        kf.update(o)
        assert_physical(kf)
    assert kf.t == obs[-1].time and kf.n_accepted >= 0.8 * len(obs)
    assert kf.n_rebase == 1


def test_an_invalid_observation_before_the_filter_starts_is_not_the_sun_either():
    # Before the filter starts, the source answers with the last raw observation: it must
    # never be one the filter refused (a NaN would be sent to the drives as a target).
    src = SunPathSource()
    t0 = pd.Timestamp("2024-04-10T08:00:00Z").timestamp()
    assert not src.observe(SunObservation(t0, float("nan"), 40.0, 0.3))
    assert src.estimate(t0 + 10.0) is None
    good = SunObservation(t0 + 60.0, 120.0, 40.0, 0.3)
    src.observe(good)
    src.observe(SunObservation(t0 + 70.0, 120.0, 140.0, 0.3))  # past the zenith
    e = src.estimate(t0 + 80.0)
    assert e is not None and (e.az_deg, e.el_deg) == (120.0, 40.0)


@pytest.mark.parametrize(
    ("site", "dlat", "dlon", "cause"),
    [
        ((33.9, 18.4), -67.8, 0.0, "likely the latitude's sign (the sky's is -33.90"),
        ((-33.9, -18.4), 0.0, 36.8, "likely the longitude's sign (the sky's is +18.40"),
        ((-33.9, 18.4), 0.0, -30.0, "likely the time stamps' zone (they read +2 h from UTC"),
        ((-45.0, 170.0), 0.2, 165.0, "the time stamps' zone (they read -11 h or +13 h from UTC"),
        (
            (33.9, 18.4),
            -67.8,
            -30.0,
            "latitude's sign (the sky's is -33.90: north is positive), and the time",
        ),
        ((33.9, 18.4), 5.0, 7.0, "check the latitude's and the longitude's signs"),
    ],
)
def test_a_site_mismatch_names_its_likely_cause(site, dlat, dlon, cause):
    from controller.sun.source import Site
    from controller.sunpath.recovery import SiteMismatch

    assert cause in SiteMismatch(dlat, dlon, 0.0).likely_cause(Site(*site))
