"""Regular per-day grids from irregular, duplicated, gappy irradiance samples.

Days are *solar* days: local mean solar time (UTC + longitude / 15 h) from midnight to
midnight, so that no daylight period is ever split across two rows (at 105 W a UTC day
cuts the afternoon in two).  The date of a row is its local mean solar date.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .solar import SECONDS_PER_DAY

#: Grid spacings that divide a day, s; the input's median spacing is rounded to one of them.
ALLOWED_STEPS_S: tuple[int, ...] = tuple(s for s in range(1, 61) if 86400 % s == 0)


@dataclass(frozen=True)
class DayGrid:
    """Samples binned onto a regular grid, one row per solar day that has data.

    Attributes
    ----------
    step_s : int
        Grid spacing, s.
    day_index : numpy.ndarray of int64, shape (days,)
        Solar day number (days since 1970-01-01 in local mean solar time).
    t0_posix : numpy.ndarray, shape (days,)
        POSIX time (UTC seconds) of slot 0 (local mean solar midnight) of each row.
    ghi : numpy.ndarray of float32, shape (days, slots)
        Mean GHI of the samples in each slot, W/m2; NaN where no sample.
    dni : numpy.ndarray of float32 or None
        Same for DNI when given.
    n_samples : numpy.ndarray of int64, shape (days,)
        Raw samples (with a finite GHI) that fell in each day, duplicates included.
    """

    step_s: int
    day_index: np.ndarray
    t0_posix: np.ndarray
    ghi: np.ndarray
    dni: np.ndarray | None
    n_samples: np.ndarray

    @property
    def n_slots(self) -> int:
        return int(round(SECONDS_PER_DAY / self.step_s))

    @property
    def dates(self) -> np.ndarray:
        """Local mean solar date of each row (numpy datetime64[D])."""
        return self.day_index.astype("datetime64[D]")


def to_posix_seconds(times) -> np.ndarray:
    """POSIX seconds (float64) from POSIX floats, numpy datetime64 or pandas UTC datetimes."""
    arr = np.asarray(times)
    if arr.dtype.kind in "fiu":
        return arr.astype(np.float64)
    if arr.dtype.kind == "M":
        return arr.astype("datetime64[ns]").astype(np.int64) / 1e9
    import pandas as pd

    idx = pd.DatetimeIndex(pd.to_datetime(arr, utc=True))
    return idx.asi8 / 1e9 if idx.unit == "ns" else idx.as_unit("ns").asi8 / 1e9


def infer_step(posix_s: np.ndarray) -> int:
    """Typical sample spacing (median of positive differences), rounded to a divisor of a day.

    Raises
    ------
    ValueError
        Fewer than two distinct times, or a spacing coarser than 60 s (the smallest
        fractal scale is one minute).
    """
    t = np.asarray(posix_s, float)
    t = t[np.isfinite(t)]
    if t.size > 200_000:
        # the first day of the record is plenty; select it by time, not by position, so
        # that shuffled input is judged on consecutive samples
        t0 = t.min()
        for span in (SECONDS_PER_DAY, 10 * SECONDS_PER_DAY, np.inf):
            sub = t[t < t0 + span]
            if sub.size >= 1000:
                break
        t = sub
    d = np.diff(np.sort(t))
    d = d[d > 0]
    if d.size == 0:
        raise ValueError("fewer than two distinct sample times")
    med = float(np.median(d))
    if med > 60.0 * 1.5:
        raise ValueError(f"median sample spacing {med:.0f} s is coarser than 60 s")
    # the smallest allowed step not finer than the data (2 % slack for clock jitter), so that
    # every slot of a complete record gets a sample (11-s data on a 10-s grid would leave
    # every tenth slot empty and count it as missing)
    steps = np.asarray(ALLOWED_STEPS_S, float)
    return int(steps[np.searchsorted(steps, 0.98 * med)]) if med <= 60.0 else 60


def build_day_grid(times, ghi, longitude: float, *, dni=None, step_s: int | None = None) -> DayGrid:
    """Bin samples onto a regular per-solar-day grid.

    Parameters
    ----------
    times : array_like
        Sample times: POSIX seconds, datetime64 or tz-aware datetimes (UTC).  Any order;
        duplicates allowed.
    ghi : array_like
        Global horizontal irradiance, W/m2; NaN marks a missing sample.
    longitude : float
        Site longitude, degrees east (sets the solar day).
    dni : array_like, optional
        Direct normal irradiance, W/m2, same length.
    step_s : int, optional
        Grid spacing; inferred from the data when omitted.

    Returns
    -------
    DayGrid
        Each sample goes to its nearest slot; several samples in a slot (duplicated
        timestamps, or sampling finer than the grid) are averaged.
    """
    t = to_posix_seconds(times)
    g = np.asarray(ghi, dtype=np.float64)
    if t.shape != g.shape:
        raise ValueError("times and ghi differ in length")
    dn = None if dni is None else np.asarray(dni, dtype=np.float64)
    if not np.all(np.isfinite(t)):  # NaT / NaN times carry no position: drop them
        keep = np.isfinite(t)
        t, g, dn = t[keep], g[keep], None if dn is None else dn[keep]
    if t.size == 0:
        raise ValueError("no sample has a valid time")
    step = int(step_s) if step_s is not None else infer_step(t)
    n_slots = int(round(SECONDS_PER_DAY / step))
    tl = t + longitude * 240.0  # local mean solar time
    slot_global = np.rint(tl / step).astype(np.int64)
    day = np.floor_divide(slot_global, n_slots)
    slot = slot_global - day * n_slots
    if np.all(day[1:] >= day[:-1]):  # usual case: days in order
        new_day = np.empty(day.size, bool)
        new_day[:1] = True
        np.not_equal(day[1:], day[:-1], out=new_day[1:])
        day_index = day[new_day]
        row = np.cumsum(new_day) - 1
    else:
        # unordered input: number the days present (bincount below averages whatever
        # lands in a slot, in any order); np.unique, not a dense table over the span, so a
        # stray far-off time costs one day, not memory for every day in between
        day_index, row = np.unique(day, return_inverse=True)
    flat = row * n_slots + slot
    size = day_index.size * n_slots

    unique_slots = bool(np.all(flat[1:] > flat[:-1]))  # ordered input without duplicates

    def binned(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ok = np.isfinite(values)
        if unique_slots:  # fast path: a scatter instead of two weighted bincounts
            grid = np.full(size, np.nan, dtype=np.float32)
            grid[flat[ok]] = values[ok]
            return grid.reshape(day_index.size, n_slots), np.bincount(row[ok], minlength=day_index.size)
        cnt = np.bincount(flat[ok], minlength=size)
        tot = np.bincount(flat[ok], weights=values[ok], minlength=size)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (tot / cnt).astype(np.float32)  # NaN where cnt == 0
        return mean.reshape(day_index.size, n_slots), np.bincount(row[ok], minlength=day_index.size)

    ghi_grid, n_samples = binned(g)
    dni_grid = None if dn is None else binned(dn)[0]
    t0 = day_index * SECONDS_PER_DAY - longitude * 240.0
    return DayGrid(
        step_s=step, day_index=day_index, t0_posix=t0, ghi=ghi_grid, dni=dni_grid, n_samples=n_samples
    )
