"""The pose module: the axis angles that face the sun."""

from __future__ import annotations

import numpy as np
import pvlib
import pytest

from controller.closedloop.pose import sun_angles
from controller.sun.types import SunEstimate
from controller.trackers import DualAxisTracker, SingleAxisTracker


@pytest.mark.parametrize("axis_tilt", [0.0, 10.0])
@pytest.mark.parametrize("az, el", [(95.0, 12.0), (200.0, 55.0), (260.0, 30.0)])
def test_the_angles_that_face_the_sun_are_pvlibs_true_tracking_unclipped(az, el, axis_tilt):
    sun = SunEstimate(0.0, az, el)
    row = SingleAxisTracker(name="r", link="l", device_id=1, axis_tilt=axis_tilt)
    tt = pvlib.tracking.singleaxis(90.0 - el, az, axis_tilt, 180.0, max_angle=90.0, backtrack=False)
    (rot,) = sun_angles(row, sun, [0.0])
    assert rot == pytest.approx(float(np.ravel(tt["tracker_theta"])[0]), abs=1e-6)
    dual = DualAxisTracker(name="d", link="l", device_id=2)
    assert sun_angles(dual, sun, [az + 350.0]) == pytest.approx([az + 360.0, el])
