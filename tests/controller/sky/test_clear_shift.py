"""A clear day's light against the sun's height times the clock to minutes, at any latitude."""

import warnings

import numpy as np
import pytest

from controller.sky import classify_days
from controller.sky.clear_shift import CLEAR_FIT_MAX, haurwitz_shape
from controller.sun.source import Site
from tests.controller.sky.test_plausibility import TROMSO, _days


def _rows(site, start, shift_h):
    df = _days(site, start, shift_h=shift_h)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return classify_days(df["time"].to_numpy(), df["ghi"].to_numpy(), site).rows


@pytest.mark.parametrize(
    "site,start",
    [
        (TROMSO, "2024-06-15"),  # the sun never sets
        (Site(-33.9, 18.4, 0.0), "2024-01-10"),
        (Site(-0.2, -78.5, 2800.0), "2024-03-20"),  # the equator: the sun climbs straight up
    ],
)
@pytest.mark.parametrize("shift_h", [-2.0, -0.25, 0.0, 1.0])
def test_the_clear_days_read_the_shift_to_two_minutes(site, start, shift_h):
    rows = _rows(site, start, shift_h)
    shifts = rows["clear_shift_h"].to_numpy(float)
    timed = np.isfinite(shifts)
    # _days cycles clear, broken, overcast (a scaled clear sky): two of three are timed
    assert timed.sum() >= 5
    assert np.abs(shifts[timed] - shift_h).max() < 2.0 / 60.0
    # the three broken days (20-min steps between 100 % and 30 % of the clear sky) are not
    assert (rows["clear_fit"].to_numpy(float) > 5 * CLEAR_FIT_MAX).sum() >= 3


def test_the_shape_is_zero_with_the_sun_down_and_grows_with_it():
    m = haurwitz_shape(np.array([-0.5, 0.0, 0.05, 0.5, 1.0]))
    assert m[0] == m[1] == 0.0 and 0.0 < m[2] < m[3] < m[4] < 1.0
