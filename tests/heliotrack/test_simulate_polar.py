"""`simulate` under a midnight sun: a dual-axis travel of one and a half turns unwinds at
the sun's lowest point (due north at Tromso), not at its hard limit in the morning."""

from datetime import UTC, datetime

import numpy as np
import pandas as pd

from heliotrack.scenario import parse_scenario
from heliotrack.simulate import run_simulation

START = datetime(2024, 6, 20, 22, 0, tzinfo=UTC)  # solar midnight at Tromso: 22:45 UTC


def test_a_midnight_sun_unwinds_the_axis_where_the_sun_is_lowest(tmp_path):
    scenario = parse_scenario(
        {
            "site": {"latitude": 69.65, "longitude": 18.96},
            "links": [{"name": "rs485-1", "kind": "modbus-rtu", "port": "hil"}],
            "trackers": [
                {
                    "name": "dual-1",
                    "type": "dual-axis",
                    "link": "rs485-1",
                    "device_id": 1,
                    "azimuth_limits": [-90.0, 450.0],
                    "stow": [180.0, 90.0],
                }
            ],
            "hil": {"substeps": 1},
        },
        "test",
    )
    run_simulation(scenario, start=START, hours=8.0, out_dir=tmp_path / "o")
    df = pd.read_csv(tmp_path / "o" / "cycles.csv")
    assert (df["true_sun_el_deg"] > 0).all() and (df["mode"] == "TRACK").all()
    jumps = np.flatnonzero(np.abs(np.diff(df["target_az_deg"].to_numpy())) > 180.0)
    assert len(jumps) == 1  # following the nearest turn alone, it unwound at 05:23, 25 deg up
    assert df["true_sun_el_deg"].iloc[jumps[0] + 1] < 5.0
    off = df[df["pointing_error_deg"] > 1.0]
    assert len(off) > 0 and off["true_sun_el_deg"].max() < 5.0  # off the sun only while it is lowest
