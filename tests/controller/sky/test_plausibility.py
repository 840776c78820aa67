"""Plausibility checks of a classified record: unit, site and clock (an audit's cases).

The audit (Cape Town, January, 1-min, 9 days) found each of these classified silently
wrong, or refused with a misleading reason; the records here are made the same way.
"""

import warnings

import numpy as np
import pandas as pd
import pvlib
import pytest

from controller.sky import classify_days
from controller.sky.grid import to_posix_seconds
from controller.sky.plausibility import check_record
from controller.sun.source import Site
from heliotrack.cli import main

CAPE_TOWN = Site(-33.9, 18.4, 0.0)
TROMSO = Site(69.6, 18.9, 0.0)


def _days(site: Site, start: str, days: int = 9, shift_h: float = 0.0, sky=None) -> pd.DataFrame:
    """1-min GHI of whole local solar days cycling clear / broken / overcast, stamped
    ``shift_h`` late (local times read as UTC); ``sky(ghi, solar_hour, clear)`` reshapes it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = pd.Timestamp(start, tz="UTC") - pd.Timedelta(hours=site.longitude / 15.0)
        t = pd.date_range(t0, periods=days * 1440, freq="60s")
        cs = pvlib.location.Location(site.latitude, site.longitude).get_clearsky(t)
    secs = (t - t0).total_seconds().to_numpy()
    day, hour = (secs // 86400).astype(int), (secs % 86400) / 3600.0
    broken = np.where((secs // 1200) % 2 == 0, 1.0, 0.3)
    factor = np.choose(day % 3, [np.ones_like(secs), broken, np.full_like(secs, 0.25)])
    ghi = cs["ghi"].to_numpy() * factor
    if sky is not None:
        ghi = sky(ghi, hour, cs)
    stamps = to_posix_seconds(t) + shift_h * 3600.0
    return pd.DataFrame({"time": stamps, "ghi": np.round(ghi, 2)})


def _tilted(site: Site, tilt: float, azimuth: float, ghi: np.ndarray, cs: pd.DataFrame) -> np.ndarray:
    """``ghi`` as a pyranometer tilted ``tilt`` deg towards ``azimuth`` would read it."""
    sun = pvlib.solarposition.get_solarposition(cs.index, site.latitude, site.longitude)
    poa = pvlib.irradiance.get_total_irradiance(
        tilt, azimuth, sun["apparent_zenith"], sun["azimuth"], cs["dni"], cs["ghi"], cs["dhi"]
    )["poa_global"]
    clear = cs["ghi"].to_numpy()
    return np.where(clear > 0, ghi * poa.fillna(0.0).to_numpy() / np.maximum(clear, 1e-9), 0.0)


def _findings(df: pd.DataFrame, site: Site) -> dict[str, bool]:
    res = classify_days(df["time"].to_numpy(), df["ghi"].to_numpy(), site)
    return {f.check: f.error for f in check_record(res, site)}


def _cli(tmp_path, df: pd.DataFrame, lat: float, lon: float, *extra: str):
    f = tmp_path / "ghi.csv"
    pd.DataFrame(
        {
            "time": pd.to_datetime(df["time"], unit="s", utc=True).dt.strftime("%Y-%m-%dT%H:%M:%SZ"),
            "ghi": df["ghi"],
        }
    ).to_csv(f, index=False)
    out = tmp_path / "out"
    rc = main(["classify", str(f), "--lat", str(lat), "--lon", str(lon), "--out", str(out), *extra])
    return rc, out


@pytest.fixture(scope="module")
def cape_town():
    return _days(CAPE_TOWN, "2024-01-10")


def test_ghi_in_kw_is_refused_and_the_unit_option_reads_it(tmp_path, cape_town, capsys):
    kw = cape_town.assign(ghi=cape_town["ghi"] / 1000.0)
    rc, out = _cli(tmp_path, kw, -33.9, 18.4)
    err = capsys.readouterr().err
    assert rc == 2 and "GHI looks like kW/m2 (values up to 1.0" in err and "--irradiance-unit kW/m2" in err
    assert not (out / "days.csv").exists()
    rc, out = _cli(tmp_path, kw, -33.9, 18.4, "--irradiance-unit", "kW/m2")
    assert rc == 0 and pd.read_csv(out / "days.csv")["class"].tolist() == ["I", "II", "III"] * 3
    # the option on W/m2 values: refused, not multiplied into 1 MW/m2
    rc, _ = _cli(tmp_path, cape_town, -33.9, 18.4, "--irradiance-unit", "kW/m2")
    assert rc == 2 and "these values look like W/m2" in capsys.readouterr().err


def test_a_wrong_latitude_sign_is_refused_naming_it(tmp_path, cape_town, capsys):
    rc, out = _cli(tmp_path, cape_town, 33.9, 18.4)  # audit: K_T 1.51-1.57, exit 0
    err = capsys.readouterr().err
    # light with the sun computed 3 deg down, centred on noon: the latitude, not the clock
    assert rc == 2 and "(--lat -33.9?)" in err and "the clock looks right" in err, err
    assert not (out / "days.csv").exists()
    # a clear week: the median K_T over 1 says it first
    clear = _days(CAPE_TOWN, "2024-01-10", sky=lambda g, h, cs: cs["ghi"].to_numpy())
    rc, _ = _cli(tmp_path, clear, 33.9, 18.4)
    err = capsys.readouterr().err
    assert rc == 2 and "(median 1.54) is over 1" in err and "(--lat -33.9?)" in err, err


def test_local_stamps_read_as_utc_are_refused_naming_the_zone(tmp_path, capsys):
    rc, _ = _cli(tmp_path, _days(CAPE_TOWN, "2024-01-10", shift_h=2.0), -33.9, 18.4)
    err = capsys.readouterr().err
    assert rc == 2 and "2.0 h late" in err and "UTC+2" in err, err


def test_a_wrong_longitude_sign_is_named(tmp_path, cape_town, capsys):
    # audit: clear days -> II, and a DNI truth on the same wrong geometry agreed 100 %
    rc, _ = _cli(tmp_path, cape_town, -33.9, -18.4)
    err = capsys.readouterr().err
    assert rc == 2 and "(--lon 18.4?" in err, err


def test_half_a_day_off_says_so_not_daylight_missing(tmp_path, capsys):
    nz = Site(-45.0, 170.0, 0.0)
    rc, _ = _cli(tmp_path, _days(nz, "2024-06-15", shift_h=12.0), -45, 170)
    err = capsys.readouterr().err
    assert rc == 2 and "UTC+12 or UTC-12" in err and "daylight missing" not in err, err


def test_light_in_a_polar_night_is_refused_naming_the_latitude(tmp_path, capsys):
    june = _days(TROMSO, "2024-06-15")
    rc, _ = _cli(tmp_path, june, -69.6, 18.9)
    err = capsys.readouterr().err
    assert rc == 2 and "(polar night) yet GHI up to" in err and "(--lat 69.6?)" in err, err
    # too few hours a day to judge the night: the "no day" message says what contradicts it
    hours = (june["time"] % 86400) / 3600.0
    rc, _ = _cli(tmp_path, june[(hours > 8) & (hours < 13)], -69.6, 18.9)
    err = capsys.readouterr().err
    assert rc == 2 and "no daylight (polar night)); yet GHI reaches" in err and "--lat/--lon signs" in err, (
        err
    )


@pytest.mark.parametrize("shift_h,error", [(1.0, True), (-1.0, True), (0.75, True)])
def test_a_clock_off_by_an_hour_at_high_latitude(shift_h, error):
    # at 69.6 N in February the sun climbs slowly: no light at night, only the edges tell
    found = _findings(_days(TROMSO, "2024-02-10", shift_h=shift_h), TROMSO)
    assert found == {"clock": error}


@pytest.mark.parametrize(
    "site,shift_h,error",
    [
        (TROMSO, 1.0, True),  # a midnight sun: no edges at all
        (TROMSO, -1.0, True),
        (Site(65.0, 10.0, 0.0), 1.0, True),  # the sun grazes the horizon for hours
        (Site(60.0, 10.0, 0.0), 0.75, True),
        (Site(60.0, 10.0, 0.0), 0.5, False),
    ],
)
def test_a_clock_off_in_a_high_summer_is_told_by_the_clear_days(site, shift_h, error):
    # the edges told nothing here: an hour (a daylight-saving mistake) and more went unseen
    found = _findings(_days(site, "2024-06-15", shift_h=shift_h), site)
    assert found == {"clock": error}


def test_the_clear_days_clock_names_the_zone_and_the_tilt(tmp_path, capsys):
    rc, out = _cli(tmp_path, _days(TROMSO, "2024-06-15", shift_h=1.0), 69.6, 18.9)
    err = capsys.readouterr().err
    assert rc == 2 and not (out / "days.csv").exists()
    assert "the clear days' light follows the sun's height 1.0 h later" in err, err
    assert "UTC+1 without a zone" in err and "tilted towards the west" in err, err


def test_a_half_hour_clock_warning_on_the_command_line(tmp_path, capsys):
    rc, out = _cli(tmp_path, _days(CAPE_TOWN, "2024-01-10", shift_h=0.5), -33.9, 18.4)
    err = capsys.readouterr().err
    assert rc == 0 and "warning" in err and "0.5 h later than the sun rises and sets" in err, err
    assert (out / "days.csv").exists()


@pytest.mark.parametrize(
    "site,start,sky",
    [
        (CAPE_TOWN, "2024-01-10", None),
        (TROMSO, "2024-02-10", None),  # low sun, K_T 0.05-0.5
        (TROMSO, "2024-06-15", None),  # midnight sun
        # a pyranometer levelled 2 deg off towards the east moves the clear days 0.22 h earlier
        (TROMSO, "2024-06-15", lambda g, h, cs: _tilted(TROMSO, 2.0, 90.0, g, cs)),
        # an afternoon storm every day moves the day's light 1.4-2.5 h from noon
        (CAPE_TOWN, "2024-01-10", lambda g, h, cs: np.where(h > 12, 0.1 * g, g)),
        (Site(60.0, 10.0, 0.0), "2024-06-15", lambda g, h, cs: np.where(h < 12, 0.1 * g, g)),
        # a dome covered until 11 h, a constant +5 W/m2 offset, a horizon that hides the morning sun
        (CAPE_TOWN, "2024-01-10", lambda g, h, cs: np.where(h < 11, np.minimum(g, 2.0), g)),
        (CAPE_TOWN, "2024-01-10", lambda g, h, cs: g + 5.0),
        (CAPE_TOWN, "2024-01-10", lambda g, h, cs: np.where(h < 9, cs["dhi"].to_numpy(), g)),
        # overcast all week: K_T about 0.05
        (CAPE_TOWN, "2024-01-10", lambda g, h, cs: 0.07 * cs["ghi"].to_numpy()),
    ],
)
def test_no_false_alarm_on_real_but_unusual_skies(site, start, sky):
    assert _findings(_days(site, start, sky=sky), site) == {}


def test_no_false_alarm_on_the_mixed_dataset(dataset_1min):
    from .conftest import SITE

    res = classify_days(dataset_1min["times"], dataset_1min["ghi"], SITE)
    assert check_record(res, SITE) == []


def test_a_dark_record_and_a_bright_day_are_warnings(cape_town):
    dark = cape_town.assign(ghi=cape_town["ghi"] * 0.01)  # up to 10.8 W/m2: no unit gives this
    assert _findings(dark, CAPE_TOWN) == {"dark": False}
    day0 = cape_town["time"] < cape_town["time"].iloc[0] + 86400
    bright = cape_town.assign(ghi=np.where(day0, 2.0 * cape_town["ghi"], cape_town["ghi"]))
    assert _findings(bright, CAPE_TOWN) == {"bright-day": False}
