"""The one time utility: every documented form, the zone rules, and the canonical writer."""

from datetime import UTC, datetime

import pytest

from controller.errors import InputError
from controller.timestamps import format_name_time, parse_timestamp, time_from_name, to_iso

T = datetime(2025, 6, 21, 10, 15, 0, tzinfo=UTC).timestamp()


@pytest.mark.parametrize(
    "name, expected",
    [
        # canonical (what heliotrack writes)
        ("2025-06-21T10-15-00Z.png", T),
        ("2025-06-21T10-15-00.250Z.png", T + 0.25),
        # ISO 8601 extended, with and without a zone
        ("2025-06-21T10:15:00Z.png", T),
        ("2025-06-21 10:15:00.5.png", T + 0.5),
        ("2025-06-21T13:45:00+03:30.jpg", T),
        # ISO 8601 basic
        ("20250621T101500Z.jpg", T),
        ("IMG_20250621_134500+0330.jpg", T),
        ("20250621T101500,125Z.tif", T + 0.125),
        # camera style: the form the two old parsers disagreed on
        ("2025-06-21-10-15-00.png", T),
        ("cam1_2025-06-21_10-15-00.jpg", T),
        ("2025-06-21T10-15-00-0300.png", T + 3 * 3600),
        # a file-name-safe zone (read as UTC before: 3.5 h off)
        ("2025-06-21T13-45-00+03-30.png", T),
        ("2025-06-21T07-15-00-03-00.png", T),
    ],
)
def test_every_documented_form(name, expected):
    assert time_from_name(name) == pytest.approx(expected, abs=1e-6)


@pytest.mark.parametrize(
    "name",
    [
        "IMG_0001.png",
        "2025-06-21.png",
        "2025-13-01T00-00-00Z.png",
        "2025-06-31T10-15-00Z.png",
        "2025-06-21T25-15-00Z.png",
        "2025-06-21T10:15-00Z.png",  # mixed time separators
        "20250621-10-15-00.png",  # basic date, extended time
        "12025-06-21T10-15-00Z.png",  # five-digit year
        "2924-03-20T08-00-00Z.png",  # a typo for 2024: outside 1900-2200
    ],
)
def test_names_without_a_valid_timestamp(name):
    assert time_from_name(name) is None


def test_only_the_file_name_is_searched():
    assert time_from_name("2025-06-21T10-15-00Z/frame.png") is None
    assert time_from_name("day/2025-06-21T10-15-00Z.png") == T


def test_canonical_round_trip():
    for t in (T, T + 0.25, T + 0.9996):
        assert time_from_name(format_name_time(t) + ".png") == pytest.approx(t, abs=5e-4)
    assert format_name_time(T) == "2025-06-21T10-15-00Z"
    assert format_name_time(T, millis=True) == "2025-06-21T10-15-00.000Z"
    assert to_iso(T) == "2025-06-21T10:15:00Z"


def test_parse_timestamp_whole_string_and_zone_rule():
    assert parse_timestamp(" 2025-06-21T10:15:00Z ") == T
    assert parse_timestamp("2025-06-21T10-15-00Z") == T
    assert parse_timestamp("2025-06-21T10:15:00") == T  # no zone: UTC
    with pytest.raises(InputError, match="has no zone"):
        parse_timestamp("2025-06-21T10:15:00", "obs.csv:3: column 'time'", require_zone=True)
    with pytest.raises(InputError, match=r"^--time: expected a time"):
        parse_timestamp("frame 2025-06-21T10:15:00Z", "--time")
    with pytest.raises(InputError):
        parse_timestamp("2025-02-30T10:15:00Z")


def test_iso_forms_may_leave_out_seconds():
    assert parse_timestamp("2025-06-21T10:15Z") == T
    assert parse_timestamp("2025-06-21 10:15") == T
    assert time_from_name("20250621T1015Z.png") == T
    assert time_from_name("2025-06-21-10-15.png") is None


def test_a_basic_date_before_a_stamp_does_not_take_its_zone():
    """An audit's case: "cam20240101_2024-03-20T08-00-00Z" had read as 2024-01-01 20:24
    with a zone -03:20 taken from the stamp that followed."""
    assert time_from_name("cam20240101_2024-03-20T08-00-00Z.png") == time_from_name(
        "2024-03-20T08-00-00Z.png"
    )
    assert time_from_name("20240320T0800+0330.png") == time_from_name("2024-03-20T08:00:00+03:30")


def test_a_year_outside_the_range_is_named():
    with pytest.raises(InputError, match=r"--start: year 2924 is outside 1900-2200"):
        parse_timestamp("2924-03-20T00:00:00Z", "--start")


def test_names_without_a_zone_are_found():
    from controller.timestamps import names_without_zone, zone_warning

    names = [
        "a/2026-03-20T10-15-00Z.png",
        "cam_2026-03-20_10-15-00.png",
        "x.png",
        "2026-03-20T10-15-00+03-30.png",
    ]
    assert names_without_zone(names) == ["cam_2026-03-20_10-15-00.png"]
    assert zone_warning([], 3) == ""
    assert zone_warning(["d/cam_2026-03-20_10-15-00.png"], 4).startswith(
        "1 of 4 frame names carry no zone (cam_2026-03-20_10-15-00.png): read as UTC"
    )
