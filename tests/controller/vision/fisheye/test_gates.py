"""The gates of the default fisheye pipeline: the sun's track without the site."""

import math

import numpy as np

from controller.sun.source import Site, solar_position
from controller.sun.types import angle_between_deg, azel_to_enu
from controller.vision.fisheye import FisheyeEstimator
from controller.vision.fisheye.gates import (
    Ephemeris,
    Gate,
    GateOptions,
    max_self_vouched_sigma,
    min_rim_share,
    track_prediction,
)

from .helpers import small_scene, truth_bundle

POLE = np.array([0.0, math.cos(math.radians(40.0)), math.sin(math.radians(40.0))])  # 40 N


def sun_at(minutes: float, dec_deg: float = 10.0) -> np.ndarray:
    """A sun on its diurnal circle (declination ``dec_deg``) ``minutes`` after some hour:
    15.04 deg/h about the celestial pole."""
    e = np.cross(POLE, [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)
    n = np.cross(POLE, e)
    h = math.radians(15.04 * minutes / 60.0)
    c, s = math.cos(math.radians(dec_deg)), math.sin(math.radians(dec_deg))
    return c * (math.cos(h) * n + math.sin(h) * e) + s * POLE


def test_the_track_of_two_anchors_puts_the_sun_where_it_is_minutes_later():
    anchors = [(0.0, sun_at(0.0)), (300.0, sun_at(5.0)), (600.0, sun_at(10.0))]
    pred, baseline = track_prediction(anchors, 900.0, 120.0)
    assert baseline == 600.0  # the longest baseline
    assert float(angle_between_deg(pred, sun_at(15.0))) < 0.01


def test_no_track_from_anchors_too_close_or_moving_unlike_the_sun():
    assert track_prediction([(0.0, sun_at(0.0)), (60.0, sun_at(1.0))], 300.0, 120.0) is None
    fast = [(0.0, sun_at(0.0)), (300.0, sun_at(50.0))]  # 2.5 deg/min: an aircraft's glint
    assert track_prediction(fast, 600.0, 120.0) is None
    assert track_prediction([(0.0, sun_at(0.0))], 600.0, 120.0) is None


def test_without_the_site_the_sequence_gate_follows_the_suns_track_and_is_tighter():
    """After a 6-min gap the gate is 1 deg + 0.3 deg/min around the last anchor (2.8 deg)
    unless the anchors give the sun's track: then it is centred where the sun is now and
    1.4 deg wide, so a fix 2 deg off the sun (a dimmed sun's halo) no longer passes."""
    scn = small_scene()
    est = FisheyeEstimator(truth_bundle(scn, site=False))
    t_last, t = 600.0, 960.0
    est._last = (t_last, sun_at(10.0))
    (plain,) = [g for g in est._gates(t, None) if g.name == "sequence"]
    assert math.isclose(plain.radius_deg, 1.0 + 0.3 * 6.0)
    est._anchors.extend([(0.0, sun_at(0.0)), (t_last, sun_at(10.0))])
    (track,) = [g for g in est._gates(t, None) if g.name == "sequence"]
    assert track.distance_deg(sun_at(16.0)) < 0.01
    assert math.isclose(track.radius_deg, 1.0 + 0.05 * 6.0 + 0.5 * 360.0 / 600.0)
    off = sun_at(16.0, dec_deg=12.0)  # 2 deg off the sun, across its track
    assert plain.distance_deg(off) < plain.radius_deg and track.distance_deg(off) > track.radius_deg


def test_the_ephemeris_computes_a_block_of_its_grid_at_once_and_stays_spas(monkeypatch):
    import controller.vision.fisheye.gates as gates

    site = Site(latitude=-33.9, longitude=18.4)
    calls = []

    def counted(*a, **kw):
        calls.append(1)
        return solar_position(*a, **kw)

    monkeypatch.setattr(gates, "solar_position", counted)
    eph = Ephemeris(site)
    t0 = 1_749_967_200.0  # 2025-06-15 06:00 UTC, on the 10-min grid
    for k in range(40):  # frames 15 min apart over 10 h
        t = t0 + 900.0 * k
        sp = solar_position(site, [t])
        if float(sp["apparent_elevation"].iloc[0]) < 3.0:
            continue  # refraction's step at the horizon: no chord follows it (and no gate there)
        truth = azel_to_enu(float(sp["azimuth"].iloc[0]), float(sp["apparent_elevation"].iloc[0]))
        # SPA's own value on the grid, its chords between (the gate is 1 deg wide)
        assert angle_between_deg(eph.direction(t), truth) < (1e-9 if k % 2 == 0 else 0.01)
    assert len(calls) <= 2  # one SPA call per 12 h block, not one per grid point


def test_a_fitted_orientation_narrows_the_ephemeris_gate_by_its_own_error():
    """What the gate lets through must be within 1 deg of the true sun even when the bundle's
    rotation is a little off: the gate is 1 deg less twice the fit's residual over the root of
    its frames.  Widened by five times the residual instead, a calibrated camera (0.05 deg)
    passed fixes 1.01 and 1.03 deg off on the third renderer's clouds."""
    from dataclasses import replace

    scn = small_scene()
    t = 1_710_936_000.0  # 2024-03-20 12:00 UTC
    plain = FisheyeEstimator(truth_bundle(scn))
    (g,) = [g for g in plain._gates(t, None) if g.name == "ephemeris"]
    assert g.radius_deg == 1.0
    b = truth_bundle(scn)
    fitted = replace(b, orientation=replace(b.orientation, residual_deg=0.05, frames=25))
    (g,) = [g for g in FisheyeEstimator(fitted)._gates(t, None) if g.name == "ephemeris"]
    assert math.isclose(g.radius_deg, 1.0 - 2.0 * 0.05 / 5.0)
    surveyed = replace(b, orientation=replace(b.orientation, residual_deg=0.2))  # no frames: one
    (g,) = [g for g in FisheyeEstimator(surveyed)._gates(t, None) if g.name == "ephemeris"]
    assert math.isclose(g.radius_deg, 0.6)


def test_a_weak_rim_is_reported_only_behind_a_gate_that_is_not_the_cameras_own_fixes():
    """No gate: a rim must hold on 70 % of its rays; the sequence gate alone (anchored on the
    camera's own fixes, which a dimmed sun's rim can lead off by steps): 50 % while that gate
    is at most 2 deg wide, 70 % when wider (minutes since its anchor); the site's
    ephemeris, a learned site's or the caller's prior vouch for any."""
    o, up = GateOptions(), np.array([0.0, 0.0, 1.0])

    def gate(name, radius_deg=1.0):
        return Gate(name, up, radius_deg, "enu")

    assert min_rim_share(o, []) == o.unvouched_min_inlier_fraction == 0.7
    assert min_rim_share(o, [gate("sequence")]) == o.sequence_min_inlier_fraction == 0.5
    assert o.sequence_vouch_max_deg == 2.0
    assert min_rim_share(o, [gate("sequence", 2.0)]) == 0.5
    assert min_rim_share(o, [gate("sequence", 2.2)]) == 0.7  # 4 minutes after its anchor
    assert min_rim_share(o, [gate("ephemeris", 1.0), gate("sequence", 5.2)]) == 0.0
    for other in ("ephemeris", "ephemeris_learned", "prior"):
        assert min_rim_share(o, [gate(other), gate("sequence")]) == 0.0
        assert min_rim_share(o, [gate(other)]) == 0.0


def test_a_wide_sigma_is_reported_only_behind_a_gate_that_is_not_the_cameras_own_fixes():
    """No gate, or the sequence's alone: a fix must be within 1 deg of the sun at 3 sigma
    (sigma <= 1/3 deg); the site's ephemeris, a learned site's or the caller's prior hold any
    fix they let through within their radius, so there is no such bound behind them."""
    o, up = GateOptions(), np.array([0.0, 0.0, 1.0])

    def gate(name, radius_deg=1.0):
        return Gate(name, up, radius_deg, "enu")

    assert max_self_vouched_sigma(o, []) == o.self_vouched_max_sigma_deg
    assert math.isclose(o.self_vouched_max_sigma_deg * 3.0, o.ephemeris_deg)
    assert max_self_vouched_sigma(o, [gate("sequence", 1.2)]) == o.self_vouched_max_sigma_deg
    for other in ("ephemeris", "ephemeris_learned", "prior"):
        assert max_self_vouched_sigma(o, [gate(other), gate("sequence")]) == math.inf
        assert max_self_vouched_sigma(o, [gate(other)]) == math.inf
