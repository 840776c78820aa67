"""The bundles' TOML text: what TOML must escape reads back as written, in either bundle."""

import tomllib
from pathlib import Path

import pytest

from controller.calibration.bundle import bundle_from_dict, load_bundle, save_bundle
from controller.calibration.camera import CameraCal
from controller.calibration.fisheye_bundle import (
    fisheye_bundle_from_dict,
    load_fisheye_bundle,
    save_fisheye_bundle,
)
from controller.calibration.toml_write import camera_section, relative_path, toml_key, toml_value
from tests.controller.calibration.test_fisheye_calibration import DOC

ODD_NOTES = {"site survey": "pole 3\nnorth-east", 'say "when"': 2, "plain": [1.5, "a\tb"]}


@pytest.mark.parametrize(
    "value",
    ['quote " and back\\slash', "new\nline, tab\t, bell\x07, del\x7f", 3, -2.5, True, [1, "x"], {"a b": 1}],
)
def test_value_reads_back(value):
    assert tomllib.loads(f"k = {toml_value(value)}")["k"] == value


def test_keys_quoted_only_where_needed():
    assert toml_key("rms_px") == "rms_px"
    assert tomllib.loads(f"{toml_key('site survey')} = 1") == {"site survey": 1}


def test_relative_path(tmp_path):
    assert relative_path(tmp_path / "m" / "mask.png", tmp_path) == str(Path("m") / "mask.png")
    assert relative_path("/elsewhere/mask.png", tmp_path) == "/elsewhere/mask.png"
    assert relative_path("mask.png", None) == "mask.png"


def test_camera_section_writes_the_model_only_when_named():
    c = CameraCal(
        width=640, height=480, fx=166.0, fy=166.0, cx=319.5, cy=239.5, dist=(0.0,) * 4, model="fisheye"
    )
    assert 'model = "fisheye"' in camera_section(c, "fisheye")
    assert not any(line.startswith("model") for line in camera_section(c))


def test_fisheye_bundle_notes_with_odd_keys_and_values(tmp_path):
    # a key with a space had been written bare and a newline raw: the bundle was refused on save
    b = fisheye_bundle_from_dict({**DOC, "notes": ODD_NOTES})
    assert load_fisheye_bundle(save_fisheye_bundle(b, tmp_path / "sky.toml")).notes == ODD_NOTES


def test_hotspot_bundle_notes_with_odd_keys_and_values(tmp_path):
    doc = {"camera": {k: v for k, v in DOC["camera"].items() if k != "model"} | {"dist": [0.0] * 5}}
    b = bundle_from_dict({**doc, "notes": ODD_NOTES})
    assert load_bundle(save_bundle(b, tmp_path / "cal.toml")).notes == ODD_NOTES
