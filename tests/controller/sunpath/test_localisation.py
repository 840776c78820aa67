import pytest

from controller.sunpath.ephemeris import transit_time
from controller.sunpath.localisation import (
    culmination_side,
    declination_from_noon,
    latitude_from_noon,
    longitude_from_noon,
)


@pytest.mark.parametrize(
    "lat,dec,side",
    [(32.5, -10.0, "south"), (-33.4, 15.0, "north"), (-33.4, -23.0, "north"), (10.0, 20.0, "north")],
)
def test_noon_formulas_round_trip(lat, dec, side):
    el = 90.0 - abs(lat - dec)
    assert latitude_from_noon(el, dec, side) == pytest.approx(lat)
    assert declination_from_noon(el, lat, side) == pytest.approx(dec)


@pytest.mark.parametrize("lon", [48.3364, -70.6693, 151.2, -179.5])
def test_longitude_from_true_noon(lon):
    tr = transit_time(1712000000.0 - lon * 240.0, lon)
    assert longitude_from_noon(tr)[0] == pytest.approx(lon, abs=0.01)


def test_culmination_side():
    assert culmination_side(183.0) == "south"
    assert culmination_side(359.0) == "north"
    assert culmination_side(5.0) == "north"
    with pytest.raises(ValueError):
        latitude_from_noon(50.0, 0.0, "east")
