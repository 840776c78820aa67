"""The sky of the emulated world: clear-sky irradiance times a cloud process.

One model feeds everything that looks at the sky (the pyranometer, the cameras' cloud
transmittance, the energy tally), so they always agree.  Clear sky is pvlib's Ineichen
model; clouds are a per-day regime:

- ``clear``: no clouds.
- ``overcast``: a continuous stratus deck: no beam, global = 20-40 % of clear sky,
  varying slowly.
- ``partly-cloudy``: broken cumulus: the sun is alternately free (beam as clear sky,
  diffuse enhanced by cloud edges) and behind a cloud (no beam, global ~35 % of clear sky),
  with exponentially distributed sun and shade spells (seeded).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pvlib

SKY_KINDS = ("clear", "overcast", "partly-cloudy")


@dataclass(frozen=True)
class SkySeries:
    """Irradiance at the sample times (W/m2) and the beam transmittance of the clouds."""

    times: np.ndarray
    ghi: np.ndarray
    dni: np.ndarray
    dhi: np.ndarray
    beam_transmittance: np.ndarray  # 1 = sun free, 0 = sun hidden
    kinds: np.ndarray  # the regime of each sample's day


def _ar1(n: int, dt: float, tau: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance AR(1) noise with correlation time ``tau`` seconds."""
    a = np.exp(-dt / tau)
    x = np.empty(n)
    x[0] = rng.standard_normal()
    e = rng.standard_normal(n) * np.sqrt(1 - a * a)
    for i in range(1, n):
        x[i] = a * x[i - 1] + e[i]
    return x


def _broken_cumulus(
    times: np.ndarray, rng: np.random.Generator, sun_s: float = 600.0, shade_s: float = 420.0
) -> np.ndarray:
    """0/1 sun visibility with exponential sun and shade spells (means in seconds)."""
    out = np.ones(times.size)
    t, state = times[0], bool(rng.random() < sun_s / (sun_s + shade_s))
    edges, states = [], []
    while t <= times[-1]:
        edges.append(t)
        states.append(state)
        t += rng.exponential(sun_s if state else shade_s)
        state = not state
    idx = np.searchsorted(np.asarray(edges), times, side="right") - 1
    out[:] = np.asarray(states, float)[idx]
    return out


def sky_series(
    times_s: np.ndarray,
    latitude: float,
    longitude: float,
    altitude: float,
    day_kinds: dict[int, str],
    linke_turbidity: float = 3.0,
    seed: int = 0,
) -> SkySeries:
    """Irradiance for ``times_s`` (POSIX s, sorted); ``day_kinds`` maps day index -> regime.

    The day index counts from the first sample's day (``(t - t0) // 86400``); days not in
    the map are clear.
    """
    times_s = np.asarray(times_s, float)
    idx = pd.DatetimeIndex(pd.to_datetime(times_s, unit="s", utc=True))
    loc = pvlib.location.Location(latitude, longitude, altitude=altitude)
    sp = loc.get_solarposition(idx)
    cs = loc.get_clearsky(idx, model="ineichen", linke_turbidity=linke_turbidity, solar_position=sp)
    ghi_c, dni_c, dhi_c = (np.nan_to_num(cs[k].to_numpy()) for k in ("ghi", "dni", "dhi"))
    cosz = np.clip(np.cos(np.radians(sp["apparent_zenith"].to_numpy())), 0, None)
    rng = np.random.default_rng(seed)
    day = ((times_s - times_s[0]) // 86400).astype(int)
    kinds = np.array([day_kinds.get(int(d), "clear") for d in day])
    ghi, dni, dhi = ghi_c.copy(), dni_c.copy(), dhi_c.copy()
    tau = np.ones(times_s.size)
    dt = float(np.median(np.diff(times_s))) if times_s.size > 1 else 60.0
    for d in np.unique(day):
        m = day == d
        kind = kinds[m][0]
        if kind == "overcast":
            k = np.clip(0.30 + 0.05 * _ar1(int(m.sum()), dt, 3600.0, rng), 0.15, 0.45)
            tau[m] = 0.0
            dni[m] = 0.0
            ghi[m] = k * ghi_c[m]
            dhi[m] = ghi[m]
        elif kind == "partly-cloudy":
            sun = _broken_cumulus(times_s[m], rng)
            tau[m] = sun
            dni[m] = dni_c[m] * sun
            diffuse = np.where(sun > 0, 1.4 * dhi_c[m], 0.35 * ghi_c[m])
            dhi[m] = diffuse
            ghi[m] = dni[m] * cosz[m] + diffuse
        elif kind != "clear":
            raise ValueError(f"unknown sky kind {kind!r}; known: {', '.join(SKY_KINDS)}")
    return SkySeries(times_s, ghi, dni, dhi, tau, kinds)
