"""What the configuration fuzzers found (issue 13), one regression test each: every case
raised something else than a ConfigError, or loaded a configuration it should not have."""

from __future__ import annotations

import datetime as dt
import math

import pytest

from controller.calibration.bundle import LobeCal, bundle_to_toml, load_bundle, update_bundle
from controller.config import load_config
from controller.errors import ConfigError
from tests.conftest import REPO

PLANT = """
[site]
latitude = 45.0
longitude = 7.0
[[links]]
name = "rs485"
kind = "modbus-rtu"
[[trackers]]
name = "row"
type = "single-axis"
link = "rs485"
device_id = 1
"""


def refused(tmp_path, text: str | bytes) -> str:
    path = tmp_path / "plant.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ConfigError) as e:
        load_config(path)
    assert str(path) in str(e.value)
    return str(e.value)


def test_nesting_deeper_than_the_recursion_limit(tmp_path):
    # was RecursionError out of tomllib
    assert "nested too deep" in refused(tmp_path, "a = " + "[" * 5000 + "]" * 5000)
    assert "nested too deep" in refused(tmp_path, "a = " + "{b=" * 3000 + "1" + "}" * 3000)


def test_an_integer_longer_than_4300_digits(tmp_path):
    # was ValueError (Python's limit on int-from-text) out of tomllib
    assert "valid TOML" in refused(tmp_path, "[site]\nlatitude = " + "9" * 5000)


def test_an_integer_too_large_for_a_float(tmp_path):
    # was OverflowError: int too large to convert to float
    msg = refused(tmp_path, PLANT.replace("latitude = 45.0", "latitude = " + "9" * 400))
    assert "site.latitude: expected a finite number" in msg


@pytest.mark.parametrize(
    ("table", "why"),
    [
        ('[sunpath]\nstate = "~nosuchuser_heliotrack/state.json"', "names no user"),  # was RuntimeError
        ('[sunpath]\nstate = "state\\u0000.json"', "without NUL"),  # was ValueError
        ('[stow]\nflag_file = "a\\u0000b"', "without NUL"),
        ('[hotspot]\ncalibration = "~nosuchuser_heliotrack/c.toml"', "names no user"),
        ('[hotspot]\ncalibration = "' + "c" * 5000 + '"', "File name too long"),  # was OSError
    ],
)
def test_paths_that_cannot_be_expanded_or_resolved(tmp_path, table, why):
    assert why in refused(tmp_path, PLANT + table)


def test_a_cross_field_rule_that_trips_on_a_bad_path(tmp_path):
    # HotspotConfig's own check resolved "frames" itself: RuntimeError / ValueError
    calib = REPO / "config" / "calibration" / "recommended.toml"
    for frames in ("~nosuchuser_heliotrack/frames", "fr\\u0000ames"):
        msg = refused(tmp_path, PLANT + f'[hotspot]\ncalibration = "{calib}"\nframes = "{frames}"')
        assert "hotspot: expected usable settings" in msg


def test_a_plant_file_without_control_gets_the_derived_defaults(tmp_path):
    """A missing [control] table used to bypass its rules: the watchdog timeout and the lead
    were NaN (DERIVED placeholders), which no drive can take."""
    path = tmp_path / "plant.toml"
    path.write_text(PLANT)
    control = load_config(path).control
    assert control.heartbeat_timeout_s == 180.0 and control.lead_s == 30.0
    assert not any(math.isnan(v) for v in vars(control).values() if isinstance(v, float))
    # and on CANopen the 3 x 60 s default must be refused, not slip through as NaN
    msg = refused(tmp_path, PLANT.replace('kind = "modbus-rtu"', 'kind = "canopen"'))
    assert "control.heartbeat_timeout_s: expected at most 65.535 s" in msg


def test_a_bundle_with_any_notes_saves_to_a_file_that_loads_back(tmp_path):
    """``[notes]`` is free-form: a date, a nested table, a key with a space or a string with a
    newline made bundle_to_toml raise TypeError or write TOML that did not load again, so
    ``heliotrack calibrate`` failed to update such a bundle."""
    src = (REPO / "config" / "calibration" / "recommended.toml").read_text()
    path = tmp_path / "bundle.toml"
    path.write_text(
        src + 'when = 2024-03-20\nrun = { by = "me", at = 12:00:00 }\n"two words" = "a\\nb\\u0001"\n'
    )
    b = update_bundle(path, lobe=LobeCal(coeff_deg=0.2))
    again = load_bundle(path)
    assert again.notes == b.notes
    assert again.notes["when"] == dt.date(2024, 3, 20) and again.notes["two words"] == "a\nb\x01"
    assert again.lobe_coeff_deg == 0.2
    assert "two words" in bundle_to_toml(again)
