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
