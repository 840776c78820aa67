"""Synthetic sun observations for the sun-path tests: pvlib SPA truth plus seeded noise."""

from __future__ import annotations

import numpy as np
import pandas as pd

from controller.sun.source import Site, solar_position
from controller.sun.types import SunObservation

ANDIMESHK = Site(32.4835, 48.3364, altitude=150.0)
SANTIAGO = Site(-33.4489, -70.6693, altitude=570.0)


def sample_times(
    first_day: str,
    n_days: int,
    utc_offset_h: float,
    start_h: float = 8.25,
    n_per_day: int = 35,
    step_s: float = 900.0,
) -> np.ndarray:
    days = pd.date_range(first_day, periods=n_days, freq="D", tz="UTC")
    t = [d.timestamp() - utc_offset_h * 3600 + start_h * 3600 + step_s * np.arange(n_per_day) for d in days]
    return np.concatenate(t)


def observations(
    site: Site, times, noise_deg: float = 0.3, az_offset_deg: float = 0.0, seed: int = 0
) -> tuple[list[SunObservation], np.ndarray, np.ndarray]:
    """Noisy observations (sensor azimuth = true + offset) and the SPA truth (az, el)."""
    rng = np.random.default_rng(seed)
    sp = solar_position(site, np.asarray(times, float))
    az, el = sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy()
    keep = el > 3.0
    t, az, el = np.asarray(times, float)[keep], az[keep], el[keep]
    el_o = el + rng.normal(0, noise_deg, el.size)
    az_o = az + az_offset_deg + rng.normal(0, noise_deg, el.size) / np.cos(np.radians(el))
    obs = [
        SunObservation(float(a), float(b % 360.0), float(c), max(noise_deg, 1e-3), sensor="test")
        for a, b, c in zip(t, az_o, el_o)
    ]
    return obs, az, el
