"""heliotrack.scoring.panel: which samples a panel's pointing error counts."""

from __future__ import annotations

import math

import numpy as np

from controller.trackers import DualAxisTracker, SingleAxisTracker
from heliotrack.scoring import panel
from hil import truth


def _enu(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def _row_sun(rotation_deg: float, row: SingleAxisTracker) -> np.ndarray:
    """A sun in the row's rotation plane that true tracking faces at ``rotation_deg``."""
    return truth.row_normal(rotation_deg, row.axis_azimuth, row.axis_tilt)


def test_a_row_counts_a_sun_its_travel_can_face_and_not_one_beyond_it():
    row = SingleAxisTracker(name="r", link="l", device_id=1, max_angle=55.0, backtrack=False)
    sun = _row_sun(-54.0, row)
    # the panel 1.5 deg off its shaft: at the -55 limit it faces -53.5, short of the sun
    _, err = panel(row, [-55.0 + 1.5], sun, [1.5])
    assert math.isnan(err)
    # the same sun with the offset the other way is within the travel, and counted
    _, err = panel(row, [-54.5], sun, [-1.5])
    assert abs(err - 0.5) < 1e-6
    # no offset given: the drive's own limits
    _, err = panel(row, [-54.0], sun)
    assert abs(err) < 1e-6


def test_a_row_does_not_count_backtracking():
    row = SingleAxisTracker(name="r", link="l", device_id=1, gcr=0.5)
    _, err = panel(row, [0.0], _row_sun(80.0, row))
    assert math.isnan(err)


def test_a_dual_axis_panel_counts_only_what_its_travel_can_face():
    dual = DualAxisTracker(
        name="d", link="l", device_id=2, azimuth_limits=(60.0, 300.0), elevation_limits=(5.0, 90.0)
    )
    assert abs(panel(dual, [180.0, 30.0], _enu(180.0, 31.0))[1] - 1.0) < 1e-6
    assert math.isnan(panel(dual, [180.0, 5.0], _enu(180.0, 3.0))[1])  # under the lowest elevation
    assert math.isnan(panel(dual, [60.0, 10.0], _enu(50.0, 10.0))[1])  # past the azimuth limit
    # an offset moves the travel: 1.5 deg down reaches a sun at 4 deg, 1.5 up not one at 89.
    assert not math.isnan(panel(dual, [180.0, 3.5], _enu(180.0, 4.0), [0.0, -1.5])[1])
    assert not math.isnan(panel(dual, [180.0, 91.5], _enu(180.0, 89.0), [0.0, 1.5])[1])
    assert math.isnan(panel(dual, [180.0, 88.5], _enu(180.0, 89.0), [0.0, -1.5])[1])
    # and turns the azimuth window: 10 deg on, a sun at 55 deg azimuth is within it
    assert not math.isnan(panel(dual, [55.0, 10.0], _enu(55.0, 10.0), [-10.0, 0.0])[1])


def test_a_whole_turn_of_azimuth_travel_faces_every_azimuth():
    dual = DualAxisTracker(name="d", link="l", device_id=2, azimuth_limits=(-180.0, 180.0))
    for az in (0.0, 90.0, 179.0, 181.0, 359.0):
        assert not math.isnan(panel(dual, [az, 20.0], _enu(az, 20.0), [3.0, 0.0])[1])
