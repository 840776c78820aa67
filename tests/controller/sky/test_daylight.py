"""The live daylight check: light while the configured site and clock put the sun down."""

import numpy as np
import pandas as pd
import pvlib
import pytest

from controller.sky.daylight import DaylightCheck, elevation_deg
from controller.sun.source import Site, solar_position

ANDIMESHK = Site(32.4835, 48.3364)


def clear_ghi(site: Site, day: str, step_s: float = 60.0, scale: float = 1.0):
    """A clear day's GHI (W/m2) at ``site`` every ``step_s``, from pvlib's Ineichen model."""
    times = pd.date_range(f"{day} 00:00", f"{day} 23:59", freq=f"{step_s:g}s", tz="UTC")
    loc = pvlib.location.Location(site.latitude, site.longitude)
    ghi = loc.get_clearsky(times, model="ineichen", linke_turbidity=3.0)["ghi"].to_numpy() * scale
    return np.array([x.timestamp() for x in times]), ghi


def feed(check: DaylightCheck, t, ghi, shift_s: float = 0.0):
    """Feed the samples; the first time (s after the day's start) the alarm stood, or None."""
    for ti, g in zip(t, ghi):
        if check.add(float(ti) + shift_s, float(g)):
            return float(ti - t[0])
    return None


@pytest.mark.parametrize("day", ["2024-03-20", "2024-06-21", "2024-12-21"])
@pytest.mark.parametrize("scale", [1.0, 0.15], ids=["clear", "overcast"])
def test_a_right_site_and_clock_raise_nothing_twilight_included(day, scale):
    check = DaylightCheck(ANDIMESHK)
    assert feed(check, *clear_ghi(ANDIMESHK, day, scale=scale)) is None and check.alarm == ""


@pytest.mark.parametrize(
    "site",
    [Site(69.65, 18.96), Site(60.0, 25.0), Site(-33.93, 18.42), Site(1.3, 103.8), Site(36.0, -120.0)],
    ids=["tromso", "60N", "cape-town", "singapore", "california"],
)
def test_other_sites_midsummer_and_midwinter_raise_nothing(site):
    for day in ("2024-06-21", "2024-12-21"):
        check = DaylightCheck(site)
        assert feed(check, *clear_ghi(site, day)) is None, day


@pytest.mark.parametrize(
    ("configured", "shift_s"),
    [
        (Site(32.4835, -48.3364), 0.0),  # the longitude's sign: the sun computed 6.4 h late
        (ANDIMESHK, -3600.0),  # the clock an hour slow: lit in the morning's computed night
        (ANDIMESHK, 3600.0),  # an hour fast: lit in the evening's
    ],
    ids=["longitude-sign", "clock-slow", "clock-fast"],
)
def test_a_wrong_site_or_clock_is_named_within_the_first_lit_night(configured, shift_s):
    t, ghi = clear_ghi(ANDIMESHK, "2024-03-20")
    check = DaylightCheck(configured)
    first = feed(check, t, ghi, shift_s)
    assert first is not None, "no alarm"
    lit = (ghi > 20.0) & (np.array([elevation_deg(configured, ti + shift_s) for ti in t]) < -3.0)
    assert first <= t[np.argmax(lit)] - t[0] + 1200.0 + 120.0  # 20 min of lit night, then at once
    assert "longitude and latitude signs" in check.alarm and "the clock" in check.alarm


def test_a_reading_after_a_gap_counts_minutes_not_the_gap():
    check = DaylightCheck(Site(32.4835, -48.3364))  # computed night until 09:50 UTC
    check.add(1710892800.0, 0.0)  # 00:00 UTC, dark
    assert check.add(1710892800.0 + 6 * 3600.0, 600.0) == ""  # 06:00, lit: 5 min, not 6 h
    assert len(check.lit) == 1 and check.lit[0][1] == 300.0


def test_the_geometry_is_spa_within_half_a_degree():
    t = np.arange(1710892800.0, 1710892800.0 + 86400.0, 900.0)
    spa = solar_position(ANDIMESHK, t)["elevation"].to_numpy()
    ours = np.array([elevation_deg(ANDIMESHK, ti) for ti in t])
    assert np.max(np.abs(ours - spa)) < 0.5  # the declination is the day's, not the hour's
