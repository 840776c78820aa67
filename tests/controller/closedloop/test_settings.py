"""``[closedloop]``: where each panel camera's frames come from."""

from __future__ import annotations

import pytest

from controller.config import load_config
from controller.errors import ConfigError
from tests.conftest import REPO

LENS = REPO / "config" / "calibration" / "panel-fisheye.toml"

PLANT = """
[site]
latitude = 32.5
longitude = 48.3
[[links]]
name = "a"
kind = "modbus-tcp"
host = "127.0.0.1"
tcp_port = 5020
[[trackers]]
name = "row-1"
type = "single-axis"
link = "a"
device_id = 1
[[trackers]]
name = "row-2"
type = "single-axis"
link = "a"
device_id = 2
[closedloop]
calibration = "{lens}"
"""


def plant(tmp_path, frames: str, trackers: str = ""):
    p = tmp_path / "plant.toml"
    p.write_text(PLANT.format(lens=LENS) + f"frames = {frames!r}\n" + trackers)
    return load_config(p)


def test_each_tracker_names_its_own_camera(tmp_path):
    cl = plant(tmp_path, "panelcams/{tracker}").closedloop
    assert cl is not None
    assert cl.camera("row-2") == str(tmp_path / "panelcams" / "row-2")  # from the plant file's folder
    url = plant(tmp_path, "rtsp://cam-{tracker}.plant/stream").closedloop
    assert url is not None and url.camera("row-1") == "rtsp://cam-row-1.plant/stream"


def test_one_camera_for_several_panels_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"closedloop\.frames: expected one camera per panel.*2 trackers"):
        plant(tmp_path, "device:0")
    # one tracker in the loop: its camera needs no name
    cl = plant(tmp_path, "device:0", 'trackers = ["row-2"]\n').closedloop
    assert cl is not None and cl.camera("row-2") == "device:0"


@pytest.mark.parametrize("frames", ["cams/{row}", "cams/{tracker", "cams/{0}"])
def test_a_field_other_than_the_trackers_name_is_refused(tmp_path, frames):
    with pytest.raises(
        ConfigError, match=r'closedloop\.frames: expected a camera address whose only field is "\{tracker\}"'
    ):
        plant(tmp_path, frames)


def test_the_simulators_renderer_stays_the_default(tmp_path):
    cl = plant(tmp_path, "hil").closedloop
    assert cl is not None and cl.frames == "hil"


def test_each_tracker_can_have_its_own_lens_bundle(tmp_path):
    """One camera model, but each unit's principal point is its own boresight."""
    for name in ("row-1", "row-2"):
        (tmp_path / f"panel-{name}.toml").write_text(LENS.read_text().replace("cx = 159.5", "cx = 160.1"))
    p = tmp_path / "plant.toml"
    p.write_text(PLANT.replace('"{lens}"', '"panel-{tracker}.toml"') + 'frames = "cams/{tracker}"\n')
    cl = load_config(p).closedloop
    assert cl is not None
    assert cl.lens("row-2") == tmp_path / "panel-row-2.toml"  # from the plant file's folder
    shared = plant(tmp_path, "cams/{tracker}").closedloop
    assert shared is not None and shared.lens("row-1") == shared.lens("row-2") == LENS


def test_a_looped_tracker_without_its_lens_bundle_is_refused(tmp_path):
    (tmp_path / "panel-row-1.toml").write_text(LENS.read_text())
    p = tmp_path / "plant.toml"
    p.write_text(PLANT.replace('"{lens}"', '"panel-{tracker}.toml"') + 'frames = "cams/{tracker}"\n')
    with pytest.raises(
        ConfigError,
        match=r"closedloop\.calibration: expected an existing file, got '/.*/panel-row-2\.toml'",
    ):
        load_config(p)
    # row-2 out of the loop: its bundle is not needed
    p.write_text(p.read_text() + 'trackers = ["row-1"]\n')
    cl = load_config(p).closedloop
    assert cl is not None and cl.trackers == ("row-1",)


@pytest.mark.parametrize(
    "calibration, expected",
    [
        ('"missing.toml"', r"closedloop\.calibration: expected an existing file"),
        (
            '"panel-{row}.toml"',
            r'closedloop\.calibration: expected a bundle\'s path whose only field is "\{tracker\}"',
        ),
    ],
)
def test_a_lens_bundle_that_cannot_be_found_is_refused(tmp_path, calibration, expected):
    p = tmp_path / "plant.toml"
    p.write_text(PLANT.replace('"{lens}"', calibration) + 'frames = "cams/{tracker}"\n')
    with pytest.raises(ConfigError, match=expected):
        load_config(p)


def test_the_learned_offsets_are_never_written_over_a_lens_bundle(tmp_path):
    """A state file that is not one is moved aside: a lens bundle named as the state would be."""
    (tmp_path / "panel-row-2.toml").write_text(LENS.read_text())
    (tmp_path / "panel-row-1.toml").write_text(LENS.read_text())
    p = tmp_path / "plant.toml"
    p.write_text(
        PLANT.replace('"{lens}"', '"panel-{tracker}.toml"')
        + 'frames = "cams/{tracker}"\nstate = "panel-row-2.toml"\n'
    )
    with pytest.raises(
        ConfigError,
        match=r"closedloop\.state: expected a file of its own \(this is closedloop\.calibration\)",
    ):
        load_config(p)


@pytest.mark.parametrize(
    "calibration, expected",
    [
        ('"~nobody-here-xyz/panel.toml"', r"expected a path \(its '~' names no user"),
        ('"' + "p" * 300 + '-{tracker}.toml"', r"expected a usable path"),
    ],
)
def test_an_unusable_lens_path_is_a_clear_error(tmp_path, calibration, expected):
    p = tmp_path / "plant.toml"
    p.write_text(PLANT.replace('"{lens}"', calibration) + 'frames = "cams/{tracker}"\n')
    with pytest.raises(ConfigError, match=r"closedloop\.calibration: " + expected):
        load_config(p)
