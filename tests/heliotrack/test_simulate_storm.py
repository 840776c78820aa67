"""A storm in `simulate` (config/hil-storm.toml): the emulated anemometer on the RS-485 line,
read between cycles, stows every row within seconds of the true gust, and the plant resumes
tracking after the dwell."""

import csv
from datetime import UTC, datetime

from heliotrack.scenario import load_scenario
from heliotrack.simulate import run_simulation
from tests.conftest import REPO


def test_storm_stows_every_row_and_resumes_after_the_dwell(tmp_path):
    cfg = load_scenario(REPO / "config" / "hil-storm.toml")
    s = run_simulation(
        cfg, start=datetime(2024, 3, 20, 7, 0, tzinfo=UTC), hours=3.5, progress=False, out_dir=tmp_path
    )
    w = s["weather"]
    assert w["storms"] == 1 and w["alarms"] == 1
    ep = w["episodes"][0]
    assert ep["stow_mode_after_s"] is not None and ep["stow_mode_after_s"] <= 60
    assert ep["stowed_after_s"] is not None and ep["stowed_after_s"] <= 180  # drive speed
    assert ep["resumed_after_s"] is not None
    assert s["modbus"]["errors"] == 0 and s["modbus"]["sensor_errors"] == 0
    assert s["modes"]["STOW"] > 0 and s["modes"]["TRACK"] > 0
    with open(tmp_path / "cycles.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert any(r["mode"] == "STOW" and r["reason"].startswith("wind: gust") for r in rows)
