"""An azimuth travel whose seam lies on the sun's path unwinds the axis while tracking."""

import pytest

from controller.config import parse_config
from controller.geometry.travel import SAMPLED_DAYS, travel_warnings, unwinding_days
from tests.controller.validate import validated


@pytest.mark.parametrize(
    ("latitude", "limits", "unwinding"),
    [
        (32.5, (0.0, 360.0), 0),  # north of the tropics: the seam north is never crossed
        (-32.5, (0.0, 360.0), SAMPLED_DAYS),  # south: the noon sun is north, every day
        (-32.5, (-180.0, 180.0), 0),
        (10.0, (0.0, 360.0), "some"),  # the tropics: the summer sun passes north of the zenith
        (10.0, (-90.0, 450.0), 0),  # a second half-turn of travel takes it
        # a midnight sun unwinds any travel once a day: at its lowest, that is not counted
        (69.65, (0.0, 360.0), 0),
        (69.65, (-90.0, 450.0), 0),  # it had unwound at the hard limit, the sun 25 deg up
        (-69.65, (-180.0, 180.0), 0),
        (-69.65, (0.0, 360.0), SAMPLED_DAYS - 4),  # the noon sun north, every day but the polar night's
    ],
)
def test_days_on_which_the_axis_unwinds(latitude, limits, unwinding):
    days = unwinding_days(latitude, 48.3, limits)
    if unwinding == "some":
        assert 0 < len(days) < SAMPLED_DAYS and all("-04-" < d[4:] < "-09-" for d in days)
    else:
        assert len(days) == unwinding


def _plant(latitude, limits):
    return parse_config(
        {
            "site": {"latitude": latitude, "longitude": 48.3},
            "links": [{"name": "a", "kind": "modbus-tcp"}],
            "trackers": [
                {
                    "name": "d",
                    "type": "dual-axis",
                    "link": "a",
                    "device_id": 1,
                    "azimuth_limits": list(limits),
                },
                {"name": "r", "type": "single-axis", "link": "a", "device_id": 2},
            ],
        }
    )


def test_a_southern_plant_with_the_northern_travel_is_warned_about(tmp_path, capsys):
    """An audit's case: latitude -32.5 with [0, 360] slewed 0 -> 359 deg at every noon."""
    (warning,) = travel_warnings(_plant(-32.5, (0.0, 360.0)))
    assert warning.startswith("trackers[0] (d): azimuth_limits [0, 360] make the axis unwind")
    assert warning.endswith("[-180, 180] suits it")
    assert travel_warnings(_plant(-32.5, (-180.0, 180.0))) == []
    assert travel_warnings(_plant(32.5, (0.0, 360.0))) == []
    out, err = validated(
        tmp_path,
        capsys,
        "[site]\nlatitude = -32.5\nlongitude = 48.3\n"
        '[[links]]\nname = "a"\nkind = "modbus-tcp"\nhost = "10.0.0.5"\n'
        '[[trackers]]\nname = "d"\ntype = "dual-axis"\nlink = "a"\ndevice_id = 1\n',
    )
    assert "ok (1 link(s), 1 tracker(s))" in out and "unwind a whole turn" in err
