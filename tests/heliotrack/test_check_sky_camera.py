"""``heliotrack check`` on a sky camera: its frame's size, and its sun against where the sun
must be (a camera moved since its orientation was calibrated fails its row)."""

import cv2
import pytest

from controller.clock import SimClock
from heliotrack.commands.check import _camera
from heliotrack.scenario import load_scenario
from hil.camera import Site as CameraSite
from hil.skycam import orientation, render_sky, sky_profile
from tests.conftest import REPO

T = 1710921600.0  # 2024-03-20T08:00:00Z: the sun about 50 deg up at Andimeshk


def checked(tmp_path, yaw_deg, t=T):
    """The check's row for a folder holding one frame of the world's sky camera turned to
    ``yaw_deg`` (its bundle was calibrated at 17)."""
    text = (REPO / "config" / "hil-fisheye.toml").read_text()
    folder = tmp_path / "frames"
    folder.mkdir()
    cfg = tmp_path / "plant.toml"
    text = text.replace('frames = "hil"', f'frames = "{folder}"')
    cfg.write_text(text.replace('calibration = "calibration/', f'calibration = "{REPO}/config/calibration/'))
    config = load_scenario(cfg)  # a ScenarioConfig is a plant Config with the world beside it
    s, cam = config.site, config.hil.skycam
    scn = sky_profile(
        cam.profile,
        noise=cam.noise,
        site=CameraSite(s.latitude, s.longitude, s.altitude),
        enu_from_camera=orientation(
            yaw_deg=yaw_deg, tilt_deg=cam.tilt_deg, tilt_azimuth_deg=cam.tilt_azimuth_deg
        ),
    )
    cv2.imwrite(str(folder / "2024-03-20T08-00-00Z.png"), render_sky(scn, t).image)
    return _camera(config, SimClock(t + 5.0), "fisheye")


def test_a_sky_camera_where_its_bundle_says_finds_the_sun_where_it_must_be(tmp_path):
    ok, text = checked(tmp_path, 17.0)
    assert ok and text.startswith("frame 640x480"), text
    far = float(text.split("the sun found ")[1].split(" deg")[0])
    assert far < 0.1, text


def test_a_sky_camera_turned_since_its_calibration_fails_its_row_with_the_offset(tmp_path):
    ok, text = checked(tmp_path, 19.0)
    assert not ok, text
    assert "deg from where the sun must be" in text and "heliotrack calibrate fisheye orientation" in text
    along = float(text.split("(")[2].split(" deg along")[0])
    assert along == pytest.approx(1.3, abs=0.3), text  # 2 deg of heading, times cos(el)


def test_at_night_there_is_nothing_to_check_the_orientation_against(tmp_path):
    ok, text = checked(tmp_path, 19.0, t=T - 6 * 3600.0)
    assert ok and "no sun to check its orientation against" in text, text
