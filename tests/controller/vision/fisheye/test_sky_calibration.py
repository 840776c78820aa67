"""A camera's sky calibration (bundle ``[orientation] sky_calibration``): the scale of each
sky model's correction by the axis's elevation, and what the bundle turns on."""

import math
from dataclasses import replace

import numpy as np
import pytest

from controller.calibration.fisheye_bundle import OrientationCal, SiteCal
from controller.vision.fisheye import FisheyeOptions
from controller.vision.fisheye.frames import with_sky_scale
from controller.vision.fisheye.skybg import calibrated_scale

CAL = (1.9, -0.15, 2.6, -0.2)
UP = np.array([0.0, 0.0, 1.0])


def _axis(el_deg: float) -> np.ndarray:
    e = math.radians(el_deg)
    return np.array([math.cos(e), 0.0, math.sin(e)])


@pytest.mark.parametrize(
    ("by_elevation", "el", "want"),
    [
        (False, 90.0, 1.9),
        (False, 30.0, 1.9 - 0.15),
        (True, 30.0, 2.6 - 0.2),
        (True, 2.0, 2.6 - 0.2 * (1 / math.sin(math.radians(5.0)) - 1)),  # held at 5 deg
    ],
)
def test_each_model_is_scaled_by_its_own_numbers_at_the_axiss_air_mass(by_elevation, el, want):
    assert calibrated_scale(CAL, by_elevation, _axis(el), UP) == pytest.approx(want)


def test_no_calibration_is_one_and_without_the_vertical_the_constant_is_used():
    assert calibrated_scale(None, True, _axis(20.0), UP) == 1.0
    assert calibrated_scale(CAL, False, _axis(20.0), None) == 1.9
    assert calibrated_scale((0.1, 0.0, 9.0, 0.0), False, _axis(20.0), UP) == 0.25  # bounds
    assert calibrated_scale((0.1, 0.0, 9.0, 0.0), True, _axis(20.0), UP) == 4.0


def test_a_bundle_with_a_calibration_turns_it_and_the_column_smear_on_and_one_without_does_not():
    M = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    base = FisheyeOptions()
    assert with_sky_scale(base, None) is base
    assert with_sky_scale(base, OrientationCal(enu_from_camera=M)) is base
    scaled = with_sky_scale(base, OrientationCal(enu_from_camera=M, sky_scale=2.0))
    assert scaled.glare.sky_scale == 2.0 and scaled.glare.sky_calibration is None
    assert not scaled.glare.column_smear
    cal = with_sky_scale(base, OrientationCal(enu_from_camera=M, sky_calibration=CAL))
    assert cal.glare.sky_calibration == CAL and cal.glare.column_smear and cal.glare.sky_scale == 1.0


def test_a_clouds_edge_is_left_out_of_the_sky_models_only_where_the_ephemeris_checks_the_fix():
    M = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    site = SiteCal(latitude=-33.45, longitude=-70.66)
    ori = OrientationCal(enu_from_camera=M)
    base = FisheyeOptions()
    assert not base.glare.cloud_edges and not base.glare.column_smear
    gated = with_sky_scale(base, ori, site).glare
    assert gated.cloud_edges and gated.column_smear  # and the smear, which the rings would read
    assert with_sky_scale(base, ori) is base  # no site: no gate to check what it accepts
    assert with_sky_scale(base, None, site) is base  # no orientation: no ephemeris gate either
    no_gate = replace(base, gates=replace(base.gates, ephemeris=False))
    assert with_sky_scale(no_gate, ori, site) is no_gate
