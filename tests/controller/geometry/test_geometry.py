"""Geometry against pvlib and against the world's independent vector maths."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.geometry import dual_axis_setpoint, single_axis_setpoint, wrap_into_range
from hil import truth


@given(st.floats(-720, 720), st.floats(-180, 0), st.floats(1, 400))
def test_wrap_into_range_is_equivalent_and_inside(angle, lo, width):
    hi = lo + width
    out = wrap_into_range(angle, lo, hi)
    assert lo - 1e-9 <= out <= hi + 1e-9
    if width >= 360:
        assert (out - angle) % 360 == pytest.approx(0, abs=1e-6) or (out - angle) % 360 == pytest.approx(
            360, abs=1e-6
        )


def test_wrap_prefers_the_representative_near_the_current_angle():
    assert wrap_into_range(10, -180, 540, near=350) == 370
    assert wrap_into_range(10, -180, 540, near=0) == 10


def test_dual_axis_normal_points_at_the_sun():
    az, el = dual_axis_setpoint(123.4, 56.7)
    sun = truth.unit_from_azel(123.4, 56.7)
    assert truth.angle_deg(truth.dual_axis_normal(az, el), sun) == pytest.approx(0, abs=1e-9)
    assert dual_axis_setpoint(100, -3)[1] == 0.0  # clamped to the elevation travel


@settings(max_examples=60, deadline=None)
@given(
    az=st.floats(0, 360),
    el=st.floats(1, 89),
    axis_az=st.sampled_from([180.0, 0.0, 170.0]),
    tilt=st.sampled_from([0.0, 5.0]),
)
def test_single_axis_true_tracking_matches_independent_geometry(az, el, axis_az, tilt):
    sp = single_axis_setpoint(az, el, axis_azimuth=axis_az, axis_tilt=tilt, max_angle=90, backtrack=False)
    sun = truth.unit_from_azel(az, el)
    if abs(sp.rotation_deg) < 89.9:
        err = truth.row_pointing_error(sp.rotation_deg, sun, axis_az, tilt)
        assert err == pytest.approx(0, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(
    az=st.floats(45, 315),
    el=st.floats(1, 89),
    gcr=st.floats(0.2, 0.6),
    slope=st.sampled_from([0.0, 4.0, -4.0]),
)
def test_backtracking_matches_the_worlds_shading_geometry(az, el, gcr, slope):
    sp = single_axis_setpoint(az, el, max_angle=60, gcr=gcr, cross_axis_tilt=slope)
    sun = truth.unit_from_azel(np.array([az]), np.array([el]))
    rot, _, bt = truth.row_ideal_rotation(sun, 180.0, 0.0, 60, gcr, slope)
    assert sp.rotation_deg == pytest.approx(rot[0], abs=1e-6)
    assert sp.backtracking == (bool(bt[0]) and abs(sp.rotation_deg - sp.true_tracking_deg) > 1e-9)


def test_east_morning_sun_turns_a_north_south_row_east():
    sp = single_axis_setpoint(90, 40, backtrack=False)
    assert sp.rotation_deg < 0  # pvlib: negative rotation faces east
    assert (
        single_axis_setpoint(90, -2).rotation_deg != single_axis_setpoint(90, -2).rotation_deg
    )  # NaN at night
