import numpy as np
import pandas as pd
import pytest

from controller.sun.source import Site, solar_position
from controller.sun.types import SunObservation
from controller.sunpath.batch import run_kalman
from controller.sunpath.days import split_days
from controller.sunpath.ephemeris import transit_time

TROMSO = Site(69.6, 18.9)


def _midnight_sun() -> tuple[np.ndarray, np.ndarray]:
    """21 June 2024 at Tromso, every 30 min from 00:00 to 23:30 UTC: the sun never sets."""
    t = pd.Timestamp("2024-06-21", tz="UTC").timestamp() + 1800.0 * np.arange(48)
    el = solar_position(TROMSO, t)["apparent_elevation"].to_numpy()
    assert el.min() > 3.0
    return t, el


@pytest.mark.parametrize("lon", [None, 18.9])
def test_a_day_of_midnight_sun_is_cut_at_its_solar_midnight(lon):
    """An audit's case: the median observation of 24-hour data was put at 12:00 (09:45 UTC
    for a 10:46 noon), so the day's last four observations made a second day dated
    2024-06-22 whose noon was the 21st's.  The cut is now at the sun's lowest, 22:44 UTC."""
    t, el = _midnight_sun()
    midnight = transit_time(t[0] + 12 * 3600.0, 18.9)[0] + 12 * 3600.0  # the 21st's noon + 12 h
    days = split_days(t, None, el, lon)
    assert [d.date for d in days] == ["2024-06-21", "2024-06-22"]
    assert t[days[0].index].max() < midnight < t[days[1].index].min()
    assert abs(days[1].midnight - midnight) < 20 * 60  # the equation of time, the fit


def test_each_row_of_a_midnight_sun_has_its_own_noon():
    t, el = _midnight_sun()
    rng = np.random.default_rng(3)
    sp = solar_position(TROMSO, t)
    obs = [
        SunObservation(float(a), float(b), float(c + rng.normal(0, 0.1)), 0.1)
        for a, b, c in zip(t, sp["azimuth"].to_numpy(), el)
    ]
    rows, _ = run_kalman(obs)
    noons = [pd.Timestamp(r.noon_utc, unit="s", tz="UTC") for r in rows]
    assert len(set(noons)) == len(rows)
    assert [n.date().isoformat() for n in noons] == [r.date for r in rows]
