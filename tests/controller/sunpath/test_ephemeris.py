import numpy as np
import pandas as pd
import pvlib
import pytest

from controller.sun.source import solar_position
from controller.sunpath.ephemeris import (
    azel_from_hour_angle,
    equation_of_time_min,
    geocentric_sun,
    transit_time,
    wrap180,
)

from ._synth import ANDIMESHK, SANTIAGO


@pytest.mark.parametrize("site", [ANDIMESHK, SANTIAGO])
def test_spherical_model_matches_spa(site):
    t = 1718000000.0 + 600.0 * np.arange(144)
    sp = solar_position(site, t)
    g = geocentric_sun(t)
    az, el = azel_from_hour_angle(
        g.hour_angle_deg(site.longitude),
        g.dec_deg,
        site.latitude,
        1.0,
        site.pressure / 100.0,
        site.temperature_c,
    )
    up = sp["apparent_elevation"].to_numpy() > 2
    assert np.abs(wrap180(az - sp["azimuth"].to_numpy()))[up].max() < 0.01
    assert np.abs(el - sp["apparent_elevation"].to_numpy())[up].max() < 0.005  # parallax


def test_transit_matches_pvlib():
    day = pd.Timestamp("2024-05-01", tz="UTC")
    ref = pvlib.solarposition.sun_rise_set_transit_spa(
        pd.DatetimeIndex([day]), SANTIAGO.latitude, SANTIAGO.longitude
    )
    got = transit_time(day.timestamp() + 16 * 3600, SANTIAGO.longitude)[0]
    assert abs(got - ref["transit"].iloc[0].timestamp()) < 1.0


def test_equation_of_time_matches_spa():
    t = 1709251200.0 + 86400.0 * np.arange(0, 360, 30)
    sp = solar_position(ANDIMESHK, t)
    assert np.abs(equation_of_time_min(t) - sp["equation_of_time"].to_numpy()).max() < 0.02
