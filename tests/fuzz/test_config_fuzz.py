"""Fuzzing the configuration loader (issue 13): arbitrary bytes, arbitrary TOML documents and
mutations of the shipped files give a ConfigError that names the file, or a valid
configuration whose limits and stow angles are consistent; never another exception."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from controller.calibration.bundle import bundle_from_dict, bundle_to_toml, load_bundle
from controller.config import Config, load_config, parse_config
from controller.errors import ConfigError
from controller.sky.settings import SkyConfig
from heliotrack.scenario import parse_scenario
from tests.conftest import REPO

from .strategies import bounded, documents, dumps, mutated, scratch_dir

CONFIGS = sorted((REPO / "config").glob("hil-*.toml"))
BASES = [tomllib.loads(p.read_text()) for p in CONFIGS]
#: A plant file with every table (no [hil]: that is the simulator's).
PLANT = tomllib.loads(
    """
[site]
name = "fuzz"
latitude = 45.0
longitude = 7.0
altitude = 300.0
[control]
period_s = 30.0
heartbeat_timeout_s = 60.0
lead_s = 10.0
min_elevation_deg = 2.0
[[links]]
name = "rs485"
kind = "modbus-rtu"
port = "/dev/ttyUSB0"
[[links]]
name = "tcp"
kind = "modbus-tcp"
host = "127.0.0.1"
tcp_port = 1502
[[links]]
name = "can"
kind = "canopen"
interface = "virtual"
channel = "can0"
[[trackers]]
name = "dual"
type = "dual-axis"
link = "rs485"
device_id = 1
azimuth_limits = [-20.0, 380.0]
elevation_limits = [5.0, 90.0]
stow = [180.0, 85.0]
[[trackers]]
name = "row"
type = "single-axis"
link = "can"
device_id = 3
max_angle = 50.0
stow = 10.0
axis_tilt = 3.0
[pyranometer]
link = "rs485"
device_id = 9
[diffuse]
enabled = true
window_h = 1.0
[wind]
link = "tcp"
device_id = 7
dual_axis_elevation_deg = 80.0
single_axis_deg = 5.0
[stow]
snow_dual_axis_elevation_deg = 30.0
flag_file = "stow.flag"
[sunspec]
enabled = true
writes_enabled = true
allow = ["127.0.0.1", "10.0.0.0/24"]
"""
)
BUNDLE = tomllib.loads((REPO / "config" / "calibration" / "recommended.toml").read_text())
_DIR = scratch_dir("heliotrack-fuzz-")


def _file(data: bytes) -> Path:
    path = _DIR / "fuzz.toml"
    path.write_bytes(data)
    return path


def check_config(cfg: Config) -> None:
    """What the rest of the controller relies on in an accepted configuration."""
    assert cfg.control.heartbeat_timeout_s > cfg.control.period_s
    for tr in cfg.trackers:
        for (lo, hi), stow in zip(tr.soft_limits, tr.stow_angles):
            assert lo < hi and lo <= stow <= hi, tr


def load_bytes(data: bytes) -> None:
    path = _file(data)
    try:
        cfg = load_config(path)
    except ConfigError as exc:
        assert str(path) in str(exc)
        return
    check_config(cfg)


@bounded(100)
@given(st.binary(max_size=300))
@example(b"\xff\xfe[site]")  # not UTF-8
@example(b"a = " + b"[" * 5000 + b"]" * 5000)  # nesting deeper than the recursion limit
@example(b"a = " + b"{b=" * 3000 + b"1" + b"}" * 3000)
@example(b"[site]\nlatitude = " + b"9" * 5000)  # past Python's int-from-text limit
def test_any_bytes_as_a_config_file(data):
    load_bytes(data)


@bounded(100)
@given(documents)
def test_any_toml_document(doc):
    load_bytes(dumps(doc).encode())


def _load_doc(doc) -> None:
    try:
        cfg = parse_config(doc, "<fuzz>")
    except ConfigError as exc:
        assert str(exc).startswith("<fuzz>")
        return
    check_config(cfg)


@bounded(300)
@given(mutated(PLANT))
@example({**PLANT, "site": {"latitude": 10**400, "longitude": 0}})  # int too large for a float
@example({**PLANT, "sunpath": {"state": "~nosuchuser_heliotrack/state.json"}})  # unknown home
@example({**PLANT, "sunpath": {"state": "state\x00.json"}})  # NUL in a path
@example({**PLANT, "stow": {"flag_file": "x" * 5000}})  # a name too long for the file system
@example({**PLANT, "hotspot": {"calibration": "y" * 5000}})
@example({**PLANT, "hotspot": {"calibration": "a\x00b"}})
@example({**PLANT, "hotspot": {"calibration": __file__, "frames": "~nosuchuser_heliotrack/f"}})
@example({**PLANT, "hotspot": {"calibration": __file__, "frames": "f\x00"}})
def test_mutated_plant_files(doc):
    _load_doc(doc)


@bounded(100)
@given(st.sampled_from(BASES).flatmap(mutated))
def test_mutated_scenario_files(doc):
    try:
        cfg = parse_scenario(doc, "<fuzz>")
    except ConfigError:
        return
    check_config(cfg)


@bounded(150)
@given(mutated(BUNDLE))
@example({**BUNDLE, "notes": {"when": __import__("datetime").date(2024, 1, 1)}})
@example({**BUNDLE, "notes": {"two words": "a\nb", "t": {"nested": 1}}})
@example({**BUNDLE, "notes": {"plumb_zenith_model": float("nan")}})  # free-form: nan is TOML
def test_calibration_bundles_load_or_are_refused_and_save_to_what_they_load(doc):
    """A bundle that loads must also save (``heliotrack calibrate`` rewrites it) to a file
    that loads back to the same bundle."""
    try:
        b = bundle_from_dict(doc, REPO / "config" / "calibration" / "fuzz.toml")
    except ConfigError:
        return
    path = _file(bundle_to_toml(b, _DIR).encode())
    again = load_bundle(path)
    assert again.camera == b.camera and again.surface == b.surface and again.pose == b.pose
    assert again.level == b.level and _same(again.notes, b.notes)


def _same(a, b) -> bool:
    """Equal, NaN included (free-form notes may hold one: TOML writes and reads ``nan``)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return bool(a == b)


SKY = {
    "method": "seed",
    "scales_s": [60, 120, 300, 600],
    "criterion": "all",
    "increments": "non-overlapping",
    "min_elevation_deg": 5.0,
    "max_missing_s": 3600,
    "kt_threshold": 0.5,
    "threshold_rule": "fixed",
    "d_thresholds": [1.2, 1.4],
    "sunshine_bands": [0.8, 0.2],
    "kt_bands": [0.65, 0.35],
}


@bounded(100)
@given(mutated(SKY))
def test_sky_settings(doc):
    try:
        SkyConfig.from_mapping(doc, "<fuzz>")
    except ConfigError:
        pass


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_the_shipped_files_still_load(path):
    from heliotrack.scenario import load_scenario

    check_config(load_scenario(path))
