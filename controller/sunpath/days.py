"""Grouping observations into observing days, and the per-day result record.

Without a time zone the "local" clock is a pseudo solar clock, so that days are cut at the
sun's lowest, the solar midnight, anywhere on Earth: mean solar time when the longitude is
known; else, when the first day's observations leave a night (a gap of
:data:`NIGHT_GAP_S` or more), the first day's median observation time is put at 12:00;
else (the sun seen round the clock: a midnight sun) the noon of the elevation's daily
harmonic is, i.e. the cut falls at the data's own lowest elevations.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from datetime import UTC, datetime

import numpy as np


@dataclass(frozen=True)
class Day:
    """Indices of one day's observations.

    Attributes
    ----------
    date : str
        Local calendar date ``YYYY-MM-DD`` (true local with a UTC offset, else pseudo-solar).
    day_number : int
        Days since 1970-01-01 on the same local clock (consecutive days differ by 1).
    midnight : float
        POSIX seconds of the local midnight starting the day.
    index : ndarray of int
        Positions of the day's observations in the input, in time order.
    """

    date: str
    day_number: int
    midnight: float
    index: np.ndarray


#: A gap in a day's observations at least this long (s) is its night; a day without one
#: (the sun seen round the clock) is cut at its lowest elevation instead.
NIGHT_GAP_S = 6 * 3600.0
_DAY_S = 86400.0


def local_offset_s(times, utc_offset_h: float | None, el_deg=None, lon_deg: float | None = None) -> float:
    """Seconds to add to UTC to get the local clock used for day boundaries.

    With ``utc_offset_h`` that is the civil offset; otherwise the offset of mean solar time
    at ``lon_deg`` (deg east) when given; else, for observations (their elevations
    ``el_deg``, deg) that leave no night in their first 24 hours, the offset that puts the
    noon of the elevation's daily harmonic ``c0 + c1 cos(wt) + c2 sin(wt)`` at 12:00;
    otherwise the offset that puts the median of the first 20 hours of observations at
    12:00.  Either way midnight falls at the sun's lowest, within minutes (the equation of
    time, at most 16.5 min; the fit).  The median of a 24-hour day had put 12:00 at
    09:45 at Tromso (18.9 E, noon 10:46 UTC), and a day's last four observations into a
    second day that repeated its noon.
    """
    if utc_offset_h is not None:
        return float(utc_offset_h) * 3600.0
    if lon_deg is not None:
        return _noon_at_12(43200.0 - float(lon_deg) * 240.0)
    t = np.asarray(times, dtype=float)
    order = np.argsort(t)
    t = t[order]
    if el_deg is not None:
        day = t < t[0] + _DAY_S
        tod = np.sort(t[day] % _DAY_S)
        gaps = np.diff(np.concatenate([tod, [tod[0] + _DAY_S]]))
        if gaps.max() < NIGHT_GAP_S:
            el = np.asarray(el_deg, dtype=float)[order][day]
            w = 2.0 * np.pi / _DAY_S
            A = np.column_stack([np.ones(tod.size), np.cos(w * t[day]), np.sin(w * t[day])])
            c = np.linalg.lstsq(A, el, rcond=None)[0]
            return _noon_at_12(float(np.arctan2(c[2], c[1])) / w)
    first = t[t < t[0] + 20 * 3600.0]
    return _noon_at_12(float(np.median(first)))


def _noon_at_12(noon_s: float) -> float:
    """The offset (s, in [-12 h, 12 h)) that puts UTC ``noon_s`` (mod a day) at 12:00."""
    return (12 * 3600.0 - noon_s % _DAY_S + 43200.0) % _DAY_S - 43200.0


def split_days(
    times, utc_offset_h: float | None = None, el_deg=None, lon_deg: float | None = None
) -> list[Day]:
    """Group POSIX ``times`` (s) into local days; see :func:`local_offset_s`."""
    t = np.asarray(times, dtype=float)
    if t.size == 0:
        return []
    off = local_offset_s(t, utc_offset_h, el_deg, lon_deg)
    num = np.floor((t + off) / 86400.0).astype(int)
    days = []
    for n in np.unique(num):
        idx = np.flatnonzero(num == n)
        idx = idx[np.argsort(t[idx], kind="stable")]
        date = datetime.fromtimestamp(n * 86400.0, tz=UTC).date().isoformat()
        days.append(Day(date, int(n), n * 86400.0 - off, idx))
    return days


@dataclass(frozen=True)
class DayResult:
    """One row of ``heliotrack sunpath`` output: what a method learned from one day.

    Attributes
    ----------
    date : str
        Local date of the day.
    noon_utc : float
        Solar noon, POSIX s.
    noon_el_deg : float
        Apparent elevation at solar noon, deg.
    declination_deg : float
        Solar declination at noon, deg (nan when the method cannot measure it).
    lat_deg, lon_deg : float
        Site estimate, deg (north-, east-positive); nan when not available.
    n_obs : int
        Observations of the day (``n_rejected`` of them rejected as outliers).
    method : str
        ``"seed"`` or ``"kalman"``.
    az_offset_deg : float
        Sensor azimuth minus true azimuth, deg.
    noon_sigma_s, lat_sigma_deg, lon_sigma_deg, dec_sigma_deg : float
        One-sigma uncertainties (nan when unknown).
    """

    date: str
    noon_utc: float
    noon_el_deg: float
    declination_deg: float
    lat_deg: float
    lon_deg: float
    n_obs: int
    method: str
    az_offset_deg: float = float("nan")
    n_rejected: int = 0
    noon_sigma_s: float = float("nan")
    lat_sigma_deg: float = float("nan")
    lon_sigma_deg: float = float("nan")
    dec_sigma_deg: float = float("nan")

    def as_row(self) -> dict:
        """Plain dict with ``noon_utc`` as ISO 8601 and floats rounded for output."""
        row = asdict(self)
        row["noon_utc"] = (
            datetime.fromtimestamp(self.noon_utc, tz=UTC).isoformat(timespec="seconds")
            if np.isfinite(self.noon_utc)
            else ""
        )
        for k, v in row.items():
            if isinstance(v, float):
                row[k] = None if not np.isfinite(v) else round(v, 6)
        return row


def why_no_noon(times, el_deg, utc_offset_h: float | None = None, shown: int = 4) -> str:
    """Why no day of these observations gives a noon, one phrase per day (the first
    ``shown`` days): too few samples, or an elevation that only rises or only sets (a
    morning's or an afternoon's samples: no maximum to fit), else unbalanced about it."""
    t = np.asarray(times, dtype=float)
    el = np.asarray(el_deg, dtype=float)
    days = split_days(t, utc_offset_h, el)
    parts = []
    for day in days[:shown]:
        e = el[day.index]
        step = np.diff(e)
        if e.size < 3:
            why = f"{e.size} sample(s), 3 at least"
        elif np.all(step > 0):
            why = "the elevation only rises (a morning: no noon in it)"
        elif np.all(step < 0):
            why = "the elevation only sets (an afternoon: no noon in it)"
        else:
            why = "too few samples on one side of its maximum"
        parts.append(f"{day.date}: {why}")
    more = f"; {len(days) - shown} more day(s)" if len(days) > shown else ""
    return "; ".join(parts) + more


def misplaced_noon(times, el_deg, utc_offset_h: float) -> str | None:
    """A warning when ``utc_offset_h`` puts the days' highest observations far from local
    noon (more than 5 h: no zone or summer time is that far off the sun): the days are cut
    at local midnight, so each day's noon would be split across two days.  None when the
    offset looks right, or there are too few days to tell."""
    t = np.asarray(times, dtype=float)
    el = np.asarray(el_deg, dtype=float)
    hours = []
    for day in split_days(t, utc_offset_h):
        if day.index.size >= 3:
            top = day.index[int(np.argmax(el[day.index]))]
            hours.append(((t[top] + utc_offset_h * 3600.0) % 86400.0) / 3600.0)
    if not hours:
        return None
    h = float(np.median(hours))
    if abs(h - 12.0) <= 5.0:
        return None
    return (
        f"--utc-offset {utc_offset_h:g}: the days' highest sun falls at {int(h):02d}:{int(h % 1 * 60):02d} "
        "local (median); days are cut at local midnight, so their noons are split: check the "
        "offset's sign and value, or leave it out"
    )
