"""The fisheye sky camera as the loop's sun source, alone and fused with the hotspot camera:
whole-sky frames rendered at the simulated time feed the one sun-path filter."""

import json

import numpy as np
import pytest

from controller.errors import ConfigError
from heliotrack.cli import main
from heliotrack.renderers import RENDERERS, camera_sensors
from heliotrack.scenario import load_scenario
from tests.conftest import REPO

FISHEYE_CONFIG = REPO / "config" / "hil-fisheye.toml"
FUSED_CONFIG = REPO / "config" / "hil-fused.toml"


def scenario(tmp_path, source=FISHEYE_CONFIG, sky="clear", period=120.0):
    text = source.read_text()
    text = text.replace("period_s = 60.0", f"period_s = {period}")
    text = text.replace("enabled = true ", "enabled = false ")  # DIFFUSE needs 1-min data
    text = text.replace('sky = "clear"', f'sky = "{sky}"')
    text = text.replace('calibration = "calibration/', f'calibration = "{REPO}/config/calibration/')
    p = tmp_path / source.name
    p.write_text(text)
    return p


def simulate(tmp_path, cfg, start="2024-03-20T06:00:00+00:00", hours=1.0):
    out = tmp_path / "out"
    args = ["simulate", "--config", str(cfg), "--start", start, "--hours", str(hours), "--out", str(out)]
    assert main([*args, "--no-report"]) == 0
    return json.loads((out / "summary.json").read_text())


def test_clear_sky_fisheye_frames_reach_the_filter_and_the_trackers_follow(tmp_path):
    s = simulate(tmp_path, scenario(tmp_path))
    frames = s["camera_frames"]
    assert frames.get("found", 0) >= 29 and sum(frames.values()) == 30  # a frame per 2-min cycle
    sp = s["sun_path"]
    assert sp["accepted"] == frames["found"] and sp["rejected"] == 0  # every one into the filter
    assert s["sources"] == {"observed": 60}  # every setpoint rests on the camera
    assert abs(sp["lat_error_deg"]) < 0.02 and abs(sp["lon_error_deg"]) < 0.02
    # A 2-minute period leads/lags the sun by up to 0.25 deg; the first cycles slew from stow.
    assert s["trackers"]["row-1"]["pointing_error_deg"]["p95"] < 0.4
    assert s["trackers"]["dual-1"]["pointing_error_deg"]["p95"] < 0.4


def test_fused_cameras_both_feed_the_one_filter(tmp_path):
    cfg = scenario(tmp_path, FUSED_CONFIG, period=600.0)
    # the paper's hotspot camera: its smaller globe image renders faster
    text = cfg.read_text().replace("calibration/recommended.toml", "calibration/seed.toml")
    cfg.write_text(text.replace('profile = "recommended"', 'profile = "seed"'))
    s = simulate(tmp_path, cfg)
    frames = s["camera_frames"]
    assert frames == {"hotspot: found": 6, "fisheye: found": 6}
    assert s["sun_path"]["accepted"] == 12  # both cameras' observations, each with its sigma
    assert s["sources"] == {"observed": 12}
    assert s["trackers"]["row-1"]["pointing_error_deg"]["p95"] < 1.5


def test_a_cloud_over_the_sun_hides_it_from_the_fisheye_too(tmp_path):
    config = load_scenario(scenario(tmp_path, sky="partly-cloudy"))
    t = 1710928800.0  # 2024-03-20T10:00Z, sun at ~50 deg
    sunny = RENDERERS["fisheye"](config, lambda _t: 1.0)(t)
    hidden = RENDERERS["fisheye"](config, lambda _t: 0.0)(t)
    assert sunny.shape == (480, 640, 3)
    assert (sunny.max(axis=2) >= 250).sum() > 100  # the saturated glare
    assert (hidden.max(axis=2) >= 250).sum() < (sunny.max(axis=2) >= 250).sum() / 5


def test_fused_needs_both_camera_tables_one_line_error(tmp_path):
    text = scenario(tmp_path, FUSED_CONFIG).read_text()
    start = text.index("\n[fisheye]\n")
    cfg = tmp_path / "fused.toml"
    cfg.write_text(text[:start] + text[text.index("\n[sunpath]\n") :])
    with pytest.raises(ConfigError) as e:
        load_scenario(cfg)
    msg = str(e.value)
    assert "\n" not in msg and str(cfg) in msg and "fisheye" in msg and "fused" in msg


def test_camera_sensors_of_each_source():
    assert camera_sensors(load_scenario(FUSED_CONFIG)) == ("hotspot", "fisheye")
    assert camera_sensors(load_scenario(FISHEYE_CONFIG)) == ("fisheye",)


def test_hil_record_writes_the_fisheye_frames(tmp_path):
    import cv2

    out = tmp_path / "frames"
    args = ["hil", "record", "--config", str(scenario(tmp_path)), "--start", "2024-03-20T06:00:00Z"]
    assert main([*args, "--hours", "0.1", "--out", str(out)]) == 0
    names = sorted(p.name for p in out.glob("*.png"))
    assert names[0] == "2024-03-20T06-00-00Z.png" and len(names) == 3  # a frame per 2-min cycle
    img = cv2.imread(str(out / names[0]), cv2.IMREAD_UNCHANGED)
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8


def test_a_bundle_calibrated_at_another_site_does_not_blind_the_loops_camera(tmp_path, caplog):
    """The shipped bundle's [site] is Andimeshk: at Cape Town its ephemeris gate had refused
    every frame (0 of 639 over a day) and the loop had tracked on the ephemeris without a
    word (an audit).  The plant's site is the gate's now, and the mismatch is said."""
    text = scenario(tmp_path).read_text()
    text = text.replace("latitude = 32.4835", "latitude = -33.9").replace(
        "longitude = 48.3364", "longitude = 18.4"
    )
    text = text.replace("azimuth_limits = [0.0, 360.0]", "azimuth_limits = [-180.0, 180.0]")
    cfg = tmp_path / "capetown.toml"
    cfg.write_text(text)
    caplog.set_level("WARNING", logger="heliotrack.sun_sources")
    s = simulate(tmp_path, cfg, start="2024-06-21T09:46:00+00:00", hours=0.5)
    assert s["camera_frames"].get("found", 0) >= 14, s["camera_frames"]
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "is not the plant's -33.9000, 18.4000: the plant's is used" in said, said


def test_a_sky_camera_turned_since_its_calibration_is_said_to_have_moved(tmp_path, caplog):
    """The world's sky camera turned 2 deg from the heading its bundle was calibrated at:
    every frame is refused by the ephemeris gate, the loop tracks on the filter, and the
    operator is told once that the camera's mount has moved (it had been silent)."""
    text = scenario(tmp_path).read_text()
    assert "yaw_deg = 17.0" in text
    cfg = tmp_path / "turned.toml"
    cfg.write_text(text.replace("yaw_deg = 17.0", "yaw_deg = 19.0"))
    caplog.set_level("INFO", logger="heliotrack.camera")
    s = simulate(tmp_path, cfg, start="2024-03-20T06:00:00+00:00", hours=1.0)
    assert s["camera_frames"].get("gate_rejected", 0) >= 25 and not s["camera_frames"].get("found")
    said = [r.getMessage() for r in caplog.records if "likely moved on its mount" in r.getMessage()]
    assert len(said) == 1 and said[0].startswith(
        "fisheye camera: its glares of the last 30 min (16 frames)"
    ), said
