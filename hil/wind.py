"""Scripted wind for the HIL: calm days, gusty days and storms with 3-s gusts.

Wind speed is a deterministic function of time (the same at every call, whatever the
sampling), so the emulated anemometer, the truth of the benchmark and a replay agree:
a slowly varying mean (per day kind, with a diurnal swing, and a storm's ramp) times a
turbulent factor built from a sum of sinusoids with a Kaimal-like spectrum
(turbulence intensity ~ 0.15-0.25, giving WMO gust factors ~ 1.4-1.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WIND_KINDS = ("calm", "gusty", "storm")
_MEAN = {"calm": 2.5, "gusty": 7.0, "storm": 7.0}  # m/s outside the storm peak
_TI = {"calm": 0.15, "gusty": 0.25, "storm": 0.22}  # turbulence intensity


@dataclass(frozen=True)
class Storm:
    """A storm: the mean wind ramps up over ``ramp_s``, holds ``peak_m_s`` for ``hold_s``,
    then falls back over ``ramp_s``."""

    start: float  # POSIX s
    peak_m_s: float = 19.0
    ramp_s: float = 1800.0
    hold_s: float = 3600.0


#: A "storm" day has a storm starting this long after the day's start (local afternoon).
STORM_DAY_START_S = 13 * 3600.0


class WindScript:
    """Wind speed (m/s) and direction at any time.

    Parameters
    ----------
    day_kinds : kind of each day (cycled), days counted from ``t0`` (POSIX s); a "storm"
        day holds a :class:`Storm` from ``STORM_DAY_START_S`` after its start
    storms : storms to add (on any day)
    seed : random seed of the turbulence phases
    """

    def __init__(
        self, t0: float, day_kinds: tuple[str, ...] = ("calm",), storms: tuple[Storm, ...] = (), seed: int = 0
    ):
        for k in day_kinds:
            if k not in WIND_KINDS:
                raise ValueError(f"unknown wind kind {k!r}; known: {', '.join(WIND_KINDS)}")
        self.t0 = float(t0)
        self.day_kinds = tuple(day_kinds) or ("calm",)
        self.storms = tuple(storms)
        rng = np.random.default_rng(seed)
        # frequencies 1/600 .. 2 Hz, log-spaced; amplitudes from a Kaimal-like spectrum
        self.freq = np.geomspace(1 / 600.0, 2.0, 48)
        f_ref = 0.02
        psd = 1.0 / (1.0 + f_ref**-1 * self.freq) ** (5 / 3)
        amp = np.sqrt(psd * np.gradient(self.freq))
        self.amp = amp / np.sqrt(np.sum(amp**2) / 2)  # unit standard deviation
        self.phase = rng.uniform(0, 2 * np.pi, self.freq.size)
        self.dir_phase = rng.uniform(0, 2 * np.pi)

    def kind(self, t: float) -> str:
        day = int(np.floor((t - self.t0) / 86400.0))
        return self.day_kinds[day % len(self.day_kinds)]

    def mean(self, t: np.ndarray) -> np.ndarray:
        """Slowly varying mean speed, m/s."""
        t = np.asarray(t, float)
        day = np.floor((t - self.t0) / 86400.0).astype(int)
        kinds = np.asarray(self.day_kinds)[day % len(self.day_kinds)]
        base = np.vectorize(_MEAN.__getitem__, otypes=[float])(kinds)
        diurnal = 1.0 + 0.3 * np.sin(2 * np.pi * ((t - self.t0) % 86400.0 / 86400.0 - 0.3))
        m = base * diurnal
        storm_days = [
            Storm(self.t0 + d * 86400.0 + STORM_DAY_START_S) for d in np.unique(day[kinds == "storm"])
        ]
        for s in (*self.storms, *storm_days):
            up = np.clip((t - s.start) / s.ramp_s, 0.0, 1.0)
            down = np.clip((s.start + s.ramp_s + s.hold_s + s.ramp_s - t) / s.ramp_s, 0.0, 1.0)
            m = np.maximum(m, s.peak_m_s * np.minimum(up, down))
        return m

    def speed(self, t) -> np.ndarray:
        """Instantaneous wind speed, m/s (>= 0)."""
        t = np.atleast_1d(np.asarray(t, float))
        ti = np.vectorize(lambda x: _TI[self.kind(x)], otypes=[float])(t)
        turb = np.sin(2 * np.pi * self.freq[None, :] * t[:, None] + self.phase[None, :]) @ self.amp
        return np.maximum(self.mean(t) * (1.0 + ti * turb), 0.0)

    def direction(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, float))
        return (240.0 + 40.0 * np.sin(2 * np.pi * t / 7200.0 + self.dir_phase)) % 360.0

    def gust(self, t: float, hold_s: float = 30.0, hz: int = 4) -> float:
        """Highest 3-s running mean of the samples in the ``hold_s`` before ``t``, m/s."""
        n3 = 3 * hz
        ts = t - np.arange(int(hold_s * hz) + n3)[::-1] / hz
        v = self.speed(ts)
        c = np.concatenate([[0.0], np.cumsum(v)])
        return float(np.max((c[n3:] - c[:-n3]) / n3))

    def mean_10min(self, t: float) -> float:
        ts = t - np.arange(0, 600.0, 1.0)
        return float(np.mean(self.speed(ts)))
