"""The hotspot camera as the loop's sun source: frames rendered at the simulated time."""

import json

from heliotrack.cli import main
from tests.conftest import REPO

HOTSPOT_CONFIG = REPO / "config" / "hil-hotspot.toml"


def scenario(tmp_path, sky="clear", period=600.0):
    text = HOTSPOT_CONFIG.read_text()
    text = text.replace("period_s = 60.0", f"period_s = {period}")
    text = text.replace("enabled = true ", "enabled = false ")  # DIFFUSE needs 1-min data
    text = text.replace('sky = "clear"', f'sky = "{sky}"')
    text = text.replace('calibration = "calibration/', f'calibration = "{REPO}/config/calibration/')
    state = tmp_path / "sunpath.json"
    text = text.replace('# state = "state/sunpath.json"', f'state = "{state}"')
    p = tmp_path / "hotspot.toml"
    p.write_text(text)
    return p, state


def simulate(tmp_path, cfg, hours=1.0):
    out = tmp_path / "out"
    assert (
        main(
            [
                "simulate",
                "--config",
                str(cfg),
                "--start",
                "2024-03-20T05:00:00+00:00",
                "--hours",
                str(hours),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return json.loads((out / "summary.json").read_text())


def test_clear_sky_tracks_on_camera_observations(tmp_path):
    cfg, state = scenario(tmp_path)
    s = simulate(tmp_path, cfg)
    assert s["sources"] == {"observed": 12}  # every setpoint rests on the camera
    assert s["modbus"]["errors"] == 0
    # A 10-minute period leads/lags the sun by up to 1.25 deg; the sensor adds ~0.1.
    assert s["trackers"]["row-1"]["pointing_error_deg"]["p95"] < 1.5
    assert state.exists()  # learned state persisted at shutdown


def test_frame_interval_leaves_the_filter_to_predict_between_frames(tmp_path):
    # One frame per 30 min, a setpoint every 10 min: the camera is read twice in the hour.
    # In between, the policy blends prediction and ephemeris; with the site given, the
    # ephemeris is the more certain and labels the other four cycles (two trackers each).
    cfg, _ = scenario(tmp_path)
    cfg.write_text(cfg.read_text().replace("interval_s = 0.0", "interval_s = 1800.0"))
    s = simulate(tmp_path, cfg)
    assert s["camera_frames"] == {"found": 2}
    assert s["sources"] == {"observed": 4, "ephemeris": 8}
    sp = s["sun_path"]
    assert sp["initialised"] and sp["accepted"] == 2 and sp["site_given"]
    assert abs(sp["lat_error_deg"]) < 0.05 and abs(sp["lon_error_deg"]) < 0.05
    assert s["trackers"]["row-1"]["pointing_error_deg"]["p95"] < 1.5


def test_overcast_sky_falls_back_without_a_camera_fix(tmp_path):
    cfg, _ = scenario(tmp_path, sky="overcast")
    s = simulate(tmp_path, cfg)
    assert "observed" not in s["sources"]  # no glint under a stratus deck
    assert set(s["sources"]) <= {"ephemeris", "predicted"}
    assert s["modbus"]["errors"] == 0


def test_hotspot_without_a_bundle_is_a_clear_error(tmp_path, capsys):
    cfg, _ = scenario(tmp_path)
    cfg.write_text(cfg.read_text().replace("recommended.toml", "missing.toml"))
    rc = main(["simulate", "--config", str(cfg), "--hours", "0.2", "--out", str(tmp_path / "o")])
    assert rc == 2
    assert "missing.toml" in capsys.readouterr().err
