"""The sky-correction scale fitted with the rotation from a day of sun detections."""

from dataclasses import replace

import numpy as np
import pytest

from benchmarks import fisheye_other as fo
from controller.calibration.fisheye_bundle import SiteCal
from controller.calibration.fisheye_orientation import sun_vectors
from controller.calibration.fisheye_sky_scale import fit_sky_calibration, fit_sky_scale
from controller.calibration.fisheye_sun_calibration import calibrate_from_sun
from controller.sun.source import Site
from controller.vision.fisheye import FisheyeEstimator
from controller.vision.fisheye.default import FisheyeOptions

SITE = Site(latitude=36.75, longitude=-4.42, altitude=20.0)


def _day(step_s: float = 900.0) -> tuple[np.ndarray, np.ndarray]:
    ts = fo.utc_midnight(2025, 3, 20) + np.arange(0, 86400, step_s)
    s = sun_vectors(SITE, ts)
    up = s[:, 2] > np.sin(np.radians(8.0))
    return ts[up], s[up]


def _rot(deg: float, axis) -> np.ndarray:
    import cv2

    return cv2.Rodrigues(np.radians(deg) * np.asarray(axis, float) / np.linalg.norm(axis))[0]


def _biased(s_enu: np.ndarray, R: np.ndarray, bias_deg: np.ndarray) -> np.ndarray:
    """Camera-frame detections of ``s_enu`` moved down by ``bias_deg`` (the sky correction
    a model under-reads: the sun read low by that much)."""
    down = np.array([0.0, 0.0, -1.0]) - s_enu * (-s_enu[:, 2:3])
    down /= np.linalg.norm(down, axis=1, keepdims=True)
    d = s_enu + np.radians(bias_deg)[:, None] * down
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d @ R  # d_cam = R^T d_enu


def test_the_scale_and_the_rotation_are_recovered_from_a_days_detections():
    """Each detection's correction (it grows as the sun sinks) read at 60 % of its true
    size: the sun found low by the 40 % left; the detections at 1.25 times the correction
    move up by a quarter of it.  The joint fit finds the scale 1 / 0.6 and the rotation."""
    ts, s = _day()
    R = _rot(3.0, [0.3, -1.0, 0.2]) @ _rot(25.0, [0, 0, 1])
    corr = 0.3 * (1.0 - s[:, 2]) ** 2  # deg: the full correction, larger for a low sun
    d1 = _biased(s, R, 0.4 * corr)
    d2 = _biased(s, R, 0.4 * corr - 0.25 * 0.6 * corr)
    fit = fit_sky_scale(ts, d1, d2, 0.25, SITE)
    assert fit.fitted == pytest.approx(1.0 / 0.6, rel=0.02)
    assert fit.scale == fit.fitted and fit.residual_deg < 0.2 * fit.residual_unscaled_deg
    cos = np.clip((np.trace(fit.enu_from_camera @ R.T) - 1) / 2, -1, 1)
    assert np.degrees(np.arccos(cos)) < 0.005


def test_a_scale_that_does_not_earn_its_place_is_left_at_one():
    """The detections scatter (0.01 deg, the same in both sets, as a frame's noise is) but
    are not biased along their corrections: the fitted scale is kept out."""
    ts, s = _day()
    R = _rot(25.0, [0, 0, 1])
    rng = np.random.default_rng(3)
    noise = np.radians(0.01) * rng.standard_normal(s.shape)  # the frame's: in both sets
    corr = 0.3 * (1.0 - s[:, 2]) ** 2
    d1 = s @ R + noise
    d2 = _biased(s, R, -0.25 * corr) + noise
    fit = fit_sky_scale(ts, d1, d2, 0.25, SITE)
    assert fit.scale == 1.0 and abs(fit.fitted - 1.0) < 0.1


def _two_models(ts, s, R, k_of):
    """Detections whose correction a model under-reads by ``1 / k``: read low by ``(k - 1) c``
    (``c``: the correction read, larger for a low sun), moving up by ``0.25 c`` at 1.25 times
    it; the suns under 20 deg modelled by elevation (``k_of(by_elevation, air mass - 1)``)."""
    by_el = s[:, 2] < np.sin(np.radians(20.0))
    x = 1.0 / s[:, 2] - 1.0
    c = 0.05 * (1.0 + x)
    k = k_of(by_el, x)
    return _biased(s, R, (k - 1.0) * c), _biased(s, R, (k - 1.25) * c), by_el


def test_four_numbers_and_the_rotation_are_recovered_when_each_model_drifts_with_air_mass():
    ts, s = _day(600.0)
    R = _rot(3.0, [0.3, -1.0, 0.2]) @ _rot(25.0, [0, 0, 1])
    true = (1.9, -0.15, 2.6, -0.2)

    def k_of(e, x):
        return np.where(e, true[2] + true[3] * x, true[0] + true[1] * x)

    d1, d2, by_el = _two_models(ts, s, R, k_of)
    one = fit_sky_scale(ts, d1, d2, 0.25, SITE)
    cal = fit_sky_calibration(ts, d1, d2, 0.25, by_el, SITE, one.residual_deg, scale=one.scale)
    np.testing.assert_allclose(cal.coefficients, true, atol=0.02)
    assert cal.adopted and cal.residual_deg < 0.2 * one.residual_deg
    cos = np.clip((np.trace(cal.enu_from_camera @ R.T) - 1) / 2, -1, 1)
    assert np.degrees(np.arccos(cos)) < 0.005


def test_four_numbers_that_do_not_cut_the_one_scales_residual_are_not_adopted():
    """One scale for both models and every elevation: the four numbers find it, and add
    nothing over the one scale (they are adopted only for a 15 % smaller residual)."""
    ts, s = _day(600.0)
    R = _rot(25.0, [0, 0, 1])
    d1, d2, by_el = _two_models(ts, s, R, lambda e, x: np.full(len(x), 1.6))
    noise = np.radians(0.005) * np.random.default_rng(5).standard_normal(d1.shape)
    d1, d2 = d1 + noise, d2 + noise
    one = fit_sky_scale(ts, d1, d2, 0.25, SITE)
    cal = fit_sky_calibration(ts, d1, d2, 0.25, by_el, SITE, one.residual_deg, scale=one.scale)
    assert not cal.adopted
    assert cal.coefficients[0] == pytest.approx(1.6, abs=0.1) and abs(cal.coefficients[1]) < 0.05


def test_a_model_seen_on_too_few_frames_keeps_the_one_scale():
    ts, s = _day(600.0)
    R = _rot(25.0, [0, 0, 1])
    d1, d2, _ = _two_models(ts, s, R, lambda e, x: 1.5 + 0.1 * x)
    few = np.zeros(len(ts), bool)
    few[:3] = True
    cal = fit_sky_calibration(ts, d1, d2, 0.25, few, SITE, 1.0, scale=1.7)
    assert cal.coefficients[2:] == (1.7, 0.0)
    assert cal.coefficients[0] == pytest.approx(1.5, abs=0.05)


def _frames(look, day, step_s):
    rays, R = fo.pixel_rays(), fo.rotation()
    rng = np.random.default_rng(17)
    ts = fo.utc_midnight(*day) + np.arange(0, 86400, step_s, dtype=float)
    _, els = fo.sun_truth(ts)
    return [(float(t), *fo.render(look, float(t), rays, R, rng)) for t in ts[els >= 5.0]]


def _rms(bundle, frames) -> float:
    """The rim's RMS (deg): the scale calibrated is the rim's (with the site, a camera may place
    the sun by its rings instead, controller.vision.fisheye.rings, which this test is not about)."""
    opts = FisheyeOptions()
    rim = replace(opts, gates=replace(opts.gates, ring_locator=False))
    est, R, errs = FisheyeEstimator(bundle, rim), np.asarray(bundle.enu_from_camera), []
    for t, img, truth in frames:
        r = est.estimate_image(img, t)
        if r.found:
            c = float(np.clip((R @ np.asarray(r.d_cam)) @ np.asarray(truth["sun_enu"]), -1, 1))
            errs.append(np.degrees(np.arccos(c)))
    return float(np.sqrt(np.mean(np.square(errs))))


@pytest.mark.parametrize(
    "look, scale, rms_without, rms_with",
    [(16, (1.7, 2.4), 0.05, 0.025), (0, (1.0, 1.0), 0.0, 0.015)],
    ids=["power-law aureole", "as described"],
)
def test_a_day_of_frames_calibrates_the_scale_that_the_next_day_needs(look, scale, rms_without, rms_with):
    """The second renderer (its lens handed over, no orientation): calibrated on 20 Mar
    (20-min frames), scored on 21 Jun.  Its power-law aureole, which the sky model reads at
    about half its strength, gets a scale of about 2 and reads 0.068 -> 0.013 deg RMS;
    its look as described, whose sky the model reads right, keeps 1 (0.0116 deg)."""
    look = fo.CLEAR_LOOKS[look]
    start = replace(fo.bundle(fo.rotation(), look), orientation=None, site=None)
    site = SiteCal(latitude=fo.SITE[0], longitude=fo.SITE[1], altitude=fo.SITE[2])
    cal_day = [(t, img) for t, img, _ in _frames(look, (2025, 3, 20), 1200.0)]
    test_day = _frames(look, (2025, 6, 21), 1800.0)
    plain = calibrate_from_sun(start, cal_day, site, refine="rotation", fit_scale=False)
    cal = calibrate_from_sun(start, cal_day, site, refine="rotation")
    ori = cal.bundle.orientation
    # the one scale, or in its place the dipole's constant (the model by elevation's frames
    # are too few on an equinox day at this site's 5-deg floor to change it)
    k = ori.sky_scale if ori.sky_calibration is None else ori.sky_calibration[0]
    assert scale[0] <= k <= scale[1]
    assert _rms(plain.bundle, test_day) >= rms_without
    assert _rms(cal.bundle, test_day) <= rms_with
