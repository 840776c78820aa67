"""`simulate` with the plant's clock off: the pyranometer's daylight at computed night
raises the SITE ALARM (controller.sky.daylight), in cycles.csv and as an event."""

import csv
from datetime import UTC, datetime

from heliotrack.scenario import parse_scenario
from heliotrack.simulate import run_simulation

START = datetime(2024, 3, 20, 2, 0, tzinfo=UTC)  # Andimeshk: sunrise 02:50 UTC


def plant(events: list[dict]):
    return parse_scenario(
        {
            "site": {"latitude": 32.4835, "longitude": 48.3364},
            "links": [{"name": "rs485-1", "kind": "modbus-rtu", "port": "hil"}],
            "trackers": [{"name": "row-1", "type": "single-axis", "link": "rs485-1", "device_id": 2}],
            "pyranometer": {"link": "rs485-1", "device_id": 10},
            "hil": {"substeps": 1, "faults": {"seed": 1, "events": events}},
        },
        "test",
    )


def alarms(out) -> list[tuple[str, str]]:
    with (out / "cycles.csv").open() as f:
        return [(r["time_utc"], r["alarms"]) for r in csv.DictReader(f) if r["alarms"]]


def test_a_plant_clock_two_hours_slow_raises_the_site_alarm_in_the_morning(tmp_path):
    # the plant's clock reads 2 h early from the start: the sun is computed below the
    # horizon until 04:50 UTC while the pyranometer sees the morning from about 03:05
    step = {"type": "wall_clock_step", "at": START.isoformat(), "duration_s": 4 * 3600, "magnitude": -7200}
    run_simulation(plant([step]), start=START, hours=3.0, out_dir=tmp_path / "slow")
    got = alarms(tmp_path / "slow")
    assert got and all("daylight while the sun is computed below the horizon" in a for _, a in got)
    # the first alarm within 20 min of lit night, then 5 min of margin (times are the plant's)
    assert datetime.fromisoformat(got[0][0]) <= datetime(2024, 3, 20, 1, 35, tzinfo=UTC), got[0]


def test_the_right_clock_raises_nothing(tmp_path):
    run_simulation(plant([]), start=START, hours=3.0, out_dir=tmp_path / "right")
    assert alarms(tmp_path / "right") == []
