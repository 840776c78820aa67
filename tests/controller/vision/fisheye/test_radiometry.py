"""Grey levels to light and back, and the lens's relative illumination."""

import math

import numpy as np

from controller.calibration.fisheye_bundle import RadiometryCal
from controller.vision.fisheye.radiometry import Radiometry


def test_a_linear_evenly_lit_camera_needs_no_conversion():
    assert Radiometry.from_cal(None) is None
    assert Radiometry.from_cal(RadiometryCal()) is None
    assert Radiometry.from_cal(RadiometryCal(vignetting=(-0.1,))) is not None


def test_srgb_decodes_as_iec_61966_2_1_and_inverts():
    r = Radiometry.from_cal(RadiometryCal(response="srgb"))
    assert r is not None
    # grey 128 is 21.6 % of full light; grey 10 is on the linear toe (10 / 255 / 12.92)
    assert abs(float(r.to_light(128.0)) / 255 - 0.2158605) < 2e-4
    assert abs(float(r.to_light(10.0)) / 255 - 10 / 255 / 12.92) < 2e-5
    g = np.linspace(0.0, 255.0, 511)
    assert np.abs(r.to_grey(r.to_light(g)) - g).max() < 0.02


def test_a_measured_table_with_flat_ends_still_inverts():
    x = np.arange(256) / 255.0
    table = np.clip((x - 0.05) / 0.85, 0.0, 1.0) ** 2.0  # crushed blacks, clipped whites
    r = Radiometry.from_cal(RadiometryCal(response="table", table=tuple(table)))
    assert r is not None
    assert (np.diff(r.light) > 0).all()
    g = np.linspace(20.0, 230.0, 211)
    assert np.abs(r.to_grey(r.to_light(g)) - g).max() < 0.05


def test_illumination_follows_the_declared_polynomial_in_field_angle():
    c = (-0.115, 0.0095, -0.0003)
    r = Radiometry.from_cal(RadiometryCal(vignetting=c))
    assert r is not None
    assert float(r.illumination(1.0)) == 1.0
    t = math.radians(60.0)
    want = 1 + c[0] * t**2 + c[1] * t**4 + c[2] * t**6
    assert abs(float(r.illumination(math.cos(t))) - want) < 1e-12
