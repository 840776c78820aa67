"""A travel wider than one turn unwinds at the sun's lowest point, not at the hard limit."""

import numpy as np
import pandas as pd
import pvlib
import pytest
from hypothesis import given
from hypothesis import strategies as st

from controller.geometry import dual_axis_setpoint, lowest_sun_azimuth, wrap_into_range
from controller.geometry.dual_axis import SEAM_HYSTERESIS_DEG


def _follow(latitude, longitude, start, hours, limits, seam):
    """The axis's targets following pvlib's sun every 5 min, and the sun at each unwinding."""
    times = pd.date_range(start, periods=int(hours * 12), freq="5min", tz="UTC")
    pos = pvlib.solarposition.get_solarposition(times, latitude, longitude)
    current, unwinds = None, []
    for az, el in zip(pos["azimuth"], pos["apparent_elevation"], strict=True):
        assert el > 0  # a midnight sun: tracked all day
        target, _ = dual_axis_setpoint(az, el, limits, (0.0, 90.0), current, seam)
        if current is not None and abs(target - current) > 180.0:
            unwinds.append((az, el))
        current = target
    return unwinds


@pytest.mark.parametrize(
    ("latitude", "start", "limits"),
    [(69.65, "2024-06-20 12:00", (-90.0, 450.0)), (-69.0, "2024-12-20 12:00", (-270.0, 270.0))],
)
def test_a_midnight_sun_unwinds_the_axis_once_a_day_at_its_lowest(latitude, start, limits):
    seam = lowest_sun_azimuth(latitude)
    unwinds = _follow(latitude, 18.96, start, 72, limits, seam)
    assert len(unwinds) == 3
    for az, el in unwinds:
        assert abs((az - seam + 180.0) % 360.0 - 180.0) <= SEAM_HYSTERESIS_DEG + 2.0
        assert el < 6.0  # the lowest sun of these days is 3-4 deg up
    # following the nearest representative alone, it unwound wherever the limit fell
    assert max(el for _, el in _follow(latitude, 18.96, start, 72, limits, None)) > 20.0


def test_the_seam_is_where_the_lower_transit_is():
    assert lowest_sun_azimuth(69.65) == 0.0 and lowest_sun_azimuth(-69.0) == 180.0
    # nearer the equator the noon sun can cross the north high in the sky: no seam
    assert lowest_sun_azimuth(60.0) is None and lowest_sun_azimuth(10.0) is None


def test_a_sun_jittering_about_the_seam_does_not_swing_the_axis():
    current = 360.0
    for az in [0.4, 359.7, 0.9, 359.2, 1.5, 358.8] * 3:
        current = wrap_into_range(az, -90.0, 450.0, near=current, seam=0.0)
        assert 355.0 < current < 365.0
    # past the hysteresis it unwinds, and stays unwound
    assert wrap_into_range(SEAM_HYSTERESIS_DEG + 0.5, -90.0, 450.0, near=370.0, seam=0.0) == pytest.approx(
        10.5
    )


def test_a_travel_that_holds_no_whole_turn_from_the_seam_keeps_the_nearest_rule():
    # [-90, 450] south of the equator: the turns from the seam are [-180, 180] and [180, 540]
    assert wrap_into_range(60.0, -90.0, 450.0, near=400.0, seam=180.0) == 420.0
    # one turn exactly: as without a seam
    for az, near in [(0.0, 359.0), (0.0, 1.0), (359.0, 0.0)]:
        assert wrap_into_range(az, 0.0, 360.0, near=near, seam=0.0) == wrap_into_range(
            az, 0.0, 360.0, near=near
        )


@given(st.floats(-720, 720), st.floats(-400, 0), st.floats(360, 800), st.sampled_from([0.0, 180.0]))
def test_with_a_seam_the_representative_is_still_inside_and_equivalent(angle, lo, width, seam):
    out = wrap_into_range(angle, lo, lo + width, near=lo + width / 3, seam=seam)
    assert lo - 1e-9 <= out <= lo + width + 1e-9
    assert np.isclose(np.cos(np.radians(out - angle)), 1.0)
