import json

import cv2
import numpy as np
import pytest

from controller.sun.types import angle_between_deg
from controller.vision import HotspotEstimator
from hil.camera import render_frame

from .helpers import small_scenario, truth_bundle, utc

T_MORNING = utc(2025, 6, 21, 5, 30)


@pytest.fixture(scope="module")
def scn():
    return small_scenario(noise=True)


@pytest.fixture(scope="module")
def est(scn):
    return HotspotEstimator(truth_bundle(scn))


@pytest.mark.parametrize("t", [utc(2025, 6, 21, 4, 0), utc(2025, 6, 21, 9, 0), utc(2025, 12, 21, 12, 0)])
def test_direction_matches_truth_in_the_model_frame(scn, est, t):
    fr = render_frame(scn, t)
    res = est.estimate_image(fr.image, t)
    assert res.found, res.reason
    err = angle_between_deg(res.s_model, fr.truth["sun_model"])
    assert err < 0.5  # quarter-size render: ~75 px globe radius
    # a wrong sign in the mirror law would put the sun ~2 x 60 deg away
    assert res.frame == "model"


def test_enu_output_with_level_and_azimuth(scn):
    from controller.sun.types import enu_to_azel
    from controller.vision import level_rotation

    s = scn.R_model_to_enu.T @ np.array([0.0, 0.6, 0.8])
    az_l, _ = enu_to_azel(level_rotation(scn.zenith_model) @ s)
    offset = float((az_l - 0.0) % 360)  # true azimuth of (0, .6, .8) is 0
    est = HotspotEstimator(truth_bundle(scn, offset=offset))
    fr = render_frame(scn, T_MORNING)
    res = est.estimate_image(fr.image, T_MORNING)
    assert res.found and res.frame == "enu"
    assert abs(res.el_deg - fr.truth["el_deg"]) < 0.5
    assert abs((res.az_deg - fr.truth["az_deg"] + 180) % 360 - 180) < 0.5
    obs = res.observation()
    assert obs.frame == "enu" and obs.sensor == "hotspot" and obs.sigma_deg > 0


def test_seed_algorithm_gives_the_same_mask_and_direction(scn):
    b = truth_bundle(scn)
    fr = render_frame(scn, T_MORNING)
    a = HotspotEstimator(b, algorithm="seed").estimate_image(fr.image)
    d = HotspotEstimator(b, algorithm="default").estimate_image(fr.image)
    assert a.found and d.found
    np.testing.assert_allclose(a.s_model, d.s_model, atol=1e-12)


def test_night_and_heavy_cloud_give_no_glint(scn, est):
    night = render_frame(scn, utc(2025, 6, 21, 20, 0))
    assert est.estimate_image(night.image).reason == "no_glint"
    cloud = render_frame(scn, T_MORNING, transmittance=0.05)
    r = est.estimate_image(cloud.image)
    assert not r.found and r.reason == "no_glint"


@pytest.mark.parametrize("tau", [0.1, 0.2, 0.3, 0.5, 0.8])
def test_clouded_sun_is_never_a_wrong_direction(scn, est, tau):
    fr = render_frame(scn, T_MORNING, transmittance=tau)
    r = est.estimate_image(fr.image)
    if r.found:
        assert angle_between_deg(r.s_model, fr.truth["sun_model"]) < 1.0


def test_overexposure_is_refused(scn, est):
    fr = render_frame(scn, T_MORNING, exposure_factor=60.0)
    r = est.estimate_image(fr.image)
    assert not r.found and r.reason == "saturated_blob_too_large"


def test_bad_frames_are_reasons_not_exceptions(scn, est, tmp_path):
    fr = render_frame(scn, T_MORNING)
    ok, buf = cv2.imencode(".jpg", fr.image)
    good = tmp_path / "good.jpg"
    good.write_bytes(buf.tobytes())
    assert est.estimate_file(good).found
    trunc = tmp_path / "trunc.jpg"
    trunc.write_bytes(buf.tobytes()[: len(buf) // 2])
    assert est.estimate_file(trunc).reason == "truncated_file"
    ok, pbuf = cv2.imencode(".png", fr.image)
    tp = tmp_path / "trunc.png"
    tp.write_bytes(pbuf.tobytes()[:-30])
    assert est.estimate_file(tp).reason == "truncated_file"
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"not an image at all")
    assert not est.estimate_file(junk).found
    assert est.estimate_file(tmp_path / "missing.png").reason == "file_not_found"
    small = tmp_path / "small.png"
    cv2.imwrite(str(small), fr.image[:100, :100])
    assert est.estimate_file(small).reason == "size_mismatch"


def test_cli_estimate_prints_json_lines(scn, tmp_path, capsys):
    from controller.calibration.bundle import save_bundle
    from heliotrack.cli import main

    bpath = save_bundle(truth_bundle(scn, level=False), tmp_path / "b.toml")
    img = tmp_path / "frame_2025-06-21T05-30-00Z.png"
    cv2.imwrite(str(img), render_frame(scn, T_MORNING).image)
    night = tmp_path / "night.png"
    cv2.imwrite(str(night), render_frame(scn, utc(2025, 6, 21, 20, 0)).image)
    rc = main(["estimate", "--sensor", "hotspot", "--calib", str(bpath), str(img), str(night)])
    assert rc == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert lines[0]["found"] and lines[0]["frame"] == "model"
    assert lines[0]["time"] == "2025-06-21T05:30:00Z"
    assert {"image", "found", "az_deg", "el_deg", "quality"} <= set(lines[0])
    assert lines[1]["found"] is False and lines[1]["reason"] == "no_glint"
    assert "time" not in lines[1]


def test_camera_sun_sensor_observes_in_enu(scn):
    """The loop's camera sensor (controller.sun.camera) on rendered frames."""
    from controller.sun.camera import CallableFrameSource, CameraSunSensor
    from controller.sun.types import azel_to_enu, enu_to_azel
    from controller.vision import level_rotation

    frames = CallableFrameSource(lambda t: render_frame(scn, t).image)
    s = scn.R_model_to_enu.T @ np.array([0.0, 0.6, 0.8])
    az_l, _ = enu_to_azel(level_rotation(scn.zenith_model) @ s)
    sensor = CameraSunSensor(frames, HotspotEstimator(truth_bundle(scn, offset=float(az_l % 360))))
    obs = sensor.observe(T_MORNING)
    truth = scn.sun([T_MORNING])["enu"][0]
    assert obs is not None and obs.frame == "enu" and obs.sensor == "hotspot"
    assert angle_between_deg(azel_to_enu(obs.az_deg, obs.el_deg), truth) < 0.5
    assert sensor.observe(utc(2025, 6, 21, 20, 0)) is None  # night: no glint
    assert sensor.outcomes["found"] == 1 and sum(sensor.outcomes.values()) == 2
    # Without levelling and azimuth alignment the direction stays in the model frame.
    model_only = CameraSunSensor(frames, HotspotEstimator(truth_bundle(scn, level=False)))
    assert model_only.observe(T_MORNING).frame == "model"
