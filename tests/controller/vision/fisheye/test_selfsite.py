"""The site learned from the sun's own sights, for a bundle with an orientation and no site."""

from dataclasses import replace

import numpy as np
import pandas as pd
import pvlib
import pytest

from controller.sun.types import azel_to_enu
from controller.vision.fisheye import FisheyeEstimator, FisheyeOptions
from controller.vision.fisheye.gates import Gate, GateOptions
from controller.vision.fisheye.selfsite import SiteFromSun, fit_site
from hil.skycam import render_sky

from .helpers import small_scene, truth_bundle, utc

SANTIAGO = (-33.45, -70.66)


def _sights(times, lat=SANTIAGO[0], lon=SANTIAGO[1]) -> np.ndarray:
    sp = pvlib.solarposition.get_solarposition(
        pd.to_datetime(np.asarray(times), unit="s", utc=True), lat, lon
    )
    return np.array([azel_to_enu(a, e) for a, e in zip(sp["azimuth"], sp["apparent_elevation"])])


def test_sights_of_the_sun_give_the_site_and_a_stray_one_is_left_out():
    ts = utc(2026, 3, 20, 13, 0) + 120.0 * np.arange(8)
    d = _sights(ts)
    d[3] = _sights([ts[3]], SANTIAGO[0] + 1.5, SANTIAGO[1])[0]  # the sun seen from 1.5 deg further north
    fit, ang = fit_site(ts, d)
    assert fit.latitude == pytest.approx(SANTIAGO[0], abs=0.05)
    assert fit.longitude == pytest.approx(SANTIAGO[1], abs=0.05)
    assert fit.n == 7 and ang[3] > 0.5 and np.delete(ang, 3).max() < 0.05


def test_a_site_is_adopted_only_when_enough_sights_over_enough_time_agree():
    learner = SiteFromSun()
    t0 = utc(2026, 3, 20, 13, 0)
    ts = t0 + 60.0 * np.arange(12)
    for k, (t, d) in enumerate(zip(ts, _sights(ts))):
        got = learner.add(float(t), d)
        assert (got is not None) == (k >= 10), k  # the tenth minute after the first
    rng = np.random.default_rng(0)
    stray = SiteFromSun()
    for t in ts:  # glares anywhere in the sky agree on no site
        v = rng.normal(size=3)
        v[2] = abs(v[2])
        assert stray.add(float(t), v / np.linalg.norm(v)) is None


def test_without_a_site_the_camera_learns_it_and_gates_by_it():
    """Clear frames every 2 min: once the sun has been seen over 10 min, a frame whose sun is
    where it was 40 minutes earlier (the clock, or a glare that is not the sun) is refused
    by the learned ephemeris, also in a new sequence; without learning it is taken."""
    scn = small_scene(noise=True)
    t0 = utc(2025, 3, 20, 5, 0)
    bundle = truth_bundle(scn, site=False)
    est = FisheyeEstimator(bundle)
    for k in range(7):
        fr = render_sky(scn, t0 + 120.0 * k)
        assert est.estimate_image(fr.image, t0 + 120.0 * k).found
    assert est.learned is not None
    fit = est.learned[0]
    assert abs(fit.latitude - scn.site.latitude) < 0.5 and abs(fit.longitude - scn.site.longitude) < 0.5
    # its gate is narrowed by the learned sun's own error, and the true sun is well inside
    (gate,) = [g for g in est._gates(t0 + 900.0, None) if g.name == "ephemeris_learned"]
    assert gate.radius_deg == pytest.approx(1.0 - 2.0 * fit.rms_deg / np.sqrt(fit.n))
    assert gate.distance_deg(_sights([t0 + 900.0], scn.site.latitude, scn.site.longitude)[0]) < 0.1
    est.reset_sequence()  # the site is the camera's: it stays
    early = render_sky(scn, t0 + 600.0)
    late = t0 + 600.0 + 2400.0
    res = est.estimate_image(early.image, late)
    assert not res.found and res.reason == "gate_rejected" and "ephemeris_learned" in res.extra["gates"]
    assert est.estimate_image(render_sky(scn, late).image, late).found
    plain = FisheyeEstimator(bundle, replace(FisheyeOptions(), gates=GateOptions(learn_site=False)))
    assert plain.learned is None and plain.estimate_image(early.image, late).found


def test_a_learned_site_that_no_longer_fits_the_camera_is_forgotten_after_two_hours():
    """Learned, then the frames' clock is 40 minutes fast: the sun is refused where the
    learned site says it cannot be; two hours after its gate first refused the sun (with no
    sight since) the site is forgotten, the sun found again and the site learned anew."""
    scn = small_scene(noise=True)
    t0 = utc(2025, 3, 20, 5, 0)
    est = FisheyeEstimator(truth_bundle(scn, site=False))
    for k in range(7):
        assert est.estimate_image(render_sky(scn, t0 + 120.0 * k).image, t0 + 120.0 * k).found
    assert est.learned is not None
    last = t0 + 720.0
    for t in (last + 1200.0, last + 8300.0):  # 40 min fast: the sun of 40 min earlier
        res = est.estimate_image(render_sky(scn, t - 2400.0).image, t)
        assert not res.found and res.reason == "gate_rejected", res.reason
    t = last + 8500.0  # more than 2 h after the first refusal
    res = est.estimate_image(render_sky(scn, t - 2400.0).image, t)
    assert res.found and est.learned is None


def test_a_learned_site_is_kept_through_a_night_without_sights():
    """A site learned one morning is the camera's the next: sights a night later do not
    drop it while they are too few, or span too little time, to fit one of their own; once
    they do, it is refitted on them.  (Before, 20 sights after the last fit the site was
    refitted on the morning's first minutes and dropped for their short span.)"""
    learner = SiteFromSun()
    t0 = utc(2026, 3, 20, 13, 0)
    day1 = t0 + 60.0 * np.arange(30)
    for t, d in zip(day1, _sights(day1)):
        learner.add(float(t), d)
    held = learner.fit
    assert held is not None and not learner.stale(float(day1[-1]) + 16 * 3600.0)  # no refusal
    day2 = t0 + 86400.0 + 30.0 * np.arange(40)
    for k, (t, d) in enumerate(zip(day2, _sights(day2))):
        fit = learner.add(float(t), d)
        assert fit is not None, k
        if t - day2[0] < 600.0:
            assert fit is held, k
    assert fit is not held and fit.latitude == pytest.approx(SANTIAGO[0], abs=0.1)


def test_a_glare_refused_at_dusk_does_not_make_the_site_forgotten_by_the_next_dawn():
    """The site's gate refuses a low glare at dusk, and nothing is seen all night: at dawn,
    14 hours on, the site is still the camera's (before, two hours after a refusal with no
    sight between had it forgotten, whatever lay between).  Refusals that run on for two
    hours, each within three of the one before, still forget it."""
    learner = SiteFromSun()
    t0 = utc(2026, 3, 20, 13, 0)
    day1 = t0 + 60.0 * np.arange(30)
    for t, d in zip(day1, _sights(day1)):
        learner.add(float(t), d)
    assert learner.fit is not None
    sun = _sights([day1[-1]])[0]
    gate = Gate("ephemeris_learned", sun, 0.9, "enu")
    off = azel_to_enu(10.0, 80.0)  # a glare nowhere near the sun
    dusk = float(day1[-1]) + 5 * 3600.0
    learner.gate_refused(dusk, [gate], [off])
    assert not learner.stale(dusk + 14 * 3600.0)  # dawn
    learner.gate_refused(dusk + 14 * 3600.0, [gate], [off])  # and one refused at dawn
    assert not learner.stale(dusk + 14 * 3600.0 + 60.0)  # starts a run of its own
    for k in range(1, 13):  # then refused every 10 min for two hours
        learner.gate_refused(dusk + 14 * 3600.0 + 600.0 * k, [gate], [off])
    assert learner.stale(dusk + 14 * 3600.0 + 7260.0)
    near = SiteFromSun()  # a glare the gate lets through is no refusal
    near.sights, near.fit = learner.sights, learner.fit
    for k in range(14):
        near.gate_refused(dusk + 600.0 * k, [gate], [sun])
    assert not near.stale(dusk + 8000.0)
