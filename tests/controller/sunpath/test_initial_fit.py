import numpy as np
import pandas as pd
import pvlib
import pytest

from controller.sun.types import SunObservation
from controller.sunpath.kalman import LAT, KalmanConfig, SunPathKalman


def _polar_winter(seed: int) -> list[SunObservation]:
    """Tromso (69.6 N, 18.9 E), 18-23 Jan 2025, every 15 min down to -0.5 deg apparent,
    SPA truth plus 0.1 deg noise on each tangent-plane axis."""
    t = pd.date_range("2025-01-18", periods=6 * 96, freq="15min", tz="UTC")
    sp = pvlib.solarposition.get_solarposition(t, 69.6, 18.9, method="nrel_numpy")
    el, az = sp["apparent_elevation"].to_numpy(), sp["azimuth"].to_numpy()
    keep = el > -0.5
    ts = (t[keep] - pd.Timestamp(0, tz="UTC")).total_seconds().to_numpy()
    el, az = el[keep], az[keep]
    rng = np.random.default_rng(seed)
    e = el + rng.normal(0, 0.1, el.size)
    a = az + rng.normal(0, 0.1, el.size) / np.cos(np.radians(el))
    return [SunObservation(float(ti), float(ai % 360), float(ei), 0.1) for ti, ai, ei in zip(ts, a, e)]


@pytest.mark.parametrize(("mode", "seed"), [("ephemeris", 17), ("free", 4)])
def test_a_sun_on_the_horizon_leaves_a_sane_latitude_sigma(mode, seed):
    """An audit's case: observations near the horizon put a model elevation on SPA's
    refraction step (true elevation -0.833 deg), where scipy's differences made a slope of
    1e5: the start's latitude sigma was 4e-7 deg and the latitude never moved again
    (ephemeris: error 0.058 deg at sigma 2e-4; free: 1.09 deg).  Now the start's sigma is
    about 0.07 deg (ephemeris) and the final error within 3 sigma."""
    kf = SunPathKalman(KalmanConfig(declination=mode))
    start_sigma = None
    for o in _polar_winter(seed):
        kf.update(o)
        if start_sigma is None and kf.initialised:
            start_sigma = kf.sigma(LAT)
    assert start_sigma is not None and start_sigma > 0.03
    err = kf.x[LAT] - 69.6
    assert 0.01 < kf.sigma(LAT) and abs(err) < 3.0 * kf.sigma(LAT), (err, kf.sigma(LAT))
