"""Whether a dual-axis tracker's azimuth travel lets it follow the sun through a day.

A travel of one turn (``[0, 360]``) has a seam: a sun whose path crosses it makes the axis
unwind a whole turn while tracking, at the moment the sun is highest if the seam faces
the equator.  ``[0, 360]`` puts the seam north, which suits sites north of the tropics;
south of the equator the noon sun is north, and ``[-180, 180]`` is the travel that suits.
"""

from __future__ import annotations

import pandas as pd
import pvlib

from .dual_axis import SEAM_HYSTERESIS_DEG, lowest_sun_azimuth, wrap_into_range

__all__ = ["SAMPLED_DAYS", "travel_warnings", "unwinding_days"]

#: Days sampled over a year (one a fortnight), each every 10 minutes.
SAMPLED_DAYS = 26


def unwinding_days(
    latitude: float,
    longitude: float,
    azimuth_limits: tuple[float, float],
    min_elevation_deg: float = 0.0,
    year: int = 2024,
) -> list[str]:
    """The sampled days on which tracking the sun within ``azimuth_limits`` turns the
    azimuth axis by more than 180 deg between two 10-minute steps (an unwinding).

    An unwinding at the sun's lowest point (within :data:`.SEAM_HYSTERESIS_DEG` and a
    step's motion of :func:`.lowest_sun_azimuth`) is not counted: under a midnight sun any
    finite travel unwinds once a day, and that is where it costs least.

    Parameters
    ----------
    latitude, longitude : float
        Site, deg (north, east).
    azimuth_limits : (float, float)
        The axis travel [min, max], deg clockwise from north (may pass 0/360).
    min_elevation_deg : float
        The sun is tracked above this elevation (deg).
    year : int
        The year sampled (the pattern repeats from year to year).

    Returns
    -------
    list of str
        ISO dates of the sampled days with an unwinding (empty: the travel suits the site).
    """
    days = pd.date_range(f"{year}-01-08", periods=SAMPLED_DAYS, freq="14D", tz="UTC")
    # local mean days, so that each sampled day is one whole daylight span
    offset = pd.Timedelta(hours=-longitude / 15.0)
    steps = pd.timedelta_range("0min", periods=144, freq="10min")
    times = pd.DatetimeIndex([d + offset + s for d in days for s in steps])
    pos = pvlib.solarposition.get_solarposition(times, latitude, longitude, method="nrel_numpy")
    az = pos["azimuth"].to_numpy().reshape(len(days), len(steps))
    el = pos["apparent_elevation"].to_numpy().reshape(len(days), len(steps))
    lo, hi = azimuth_limits
    seam = lowest_sun_azimuth(latitude)
    out = []
    for k, day in enumerate(days):
        current: float | None = None
        for a, e in zip(az[k], el[k], strict=True):
            if e < min_elevation_deg:
                current = None  # at night the tracker parks; the morning starts afresh
                continue
            target = wrap_into_range(float(a), lo, hi, near=current, seam=seam)
            if current is not None and abs(target - current) > 180.0:
                off_seam = 180.0 if seam is None else abs((float(a) - seam + 180.0) % 360.0 - 180.0)
                if off_seam > SEAM_HYSTERESIS_DEG + 5.0:
                    out.append(day.date().isoformat())
                    break
            current = target
    return out


def travel_warnings(config) -> list[str]:
    """One line per dual-axis tracker of ``config`` (a :class:`controller.config.Config`)
    whose azimuth travel unwinds while tracking at the configured site."""
    from ..config import DualAxisTracker

    out = []
    for i, tr in enumerate(config.trackers):
        if not isinstance(tr, DualAxisTracker):
            continue
        days = unwinding_days(
            config.site.latitude, config.site.longitude, tr.azimuth_limits, config.control.min_elevation_deg
        )
        if days:
            lo, hi = tr.azimuth_limits
            better = "[-180, 180]" if config.site.latitude < 0 else "[0, 360]"
            out.append(
                f"trackers[{i}] ({tr.name}): azimuth_limits [{lo:g}, {hi:g}] make the axis unwind a "
                f"whole turn while tracking on {len(days)} of {SAMPLED_DAYS} days sampled over a year "
                f"(first {days[0]}): the sun's path crosses the travel's seam at this site"
                + (f"; {better} suits it" if better != f"[{lo:g}, {hi:g}]" else "")
            )
    return out
