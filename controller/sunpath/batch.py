"""The sun-path filter over a batch of observations (a CSV, a benchmark): one row a day."""

from __future__ import annotations

import numpy as np

from ..sun.source import Site
from ..sun.types import SunObservation
from .days import DayResult, split_days
from .kalman import KalmanConfig, SunPathKalman


def run_kalman(
    observations: list[SunObservation],
    config: KalmanConfig | None = None,
    site: Site | None = None,
    utc_offset_h: float | None = None,
    kf: SunPathKalman | None = None,
) -> tuple[list[DayResult], SunPathKalman]:
    """Run the filter over observations (any order) and summarise each local day.

    Each day's row is the filter's state after that day's last observation (a filtered,
    not smoothed, estimate); days before the filter could start give no row.  Without
    ``utc_offset_h`` days are cut at the solar midnight (:func:`.days.local_offset_s`:
    the site's longitude when known, else the observations' own).
    """
    kf = kf or SunPathKalman(config, site)
    obs = sorted(observations, key=lambda o: o.time)
    times = np.array([o.time for o in obs])
    results = []
    known = site or kf.site
    lon = known.longitude if known is not None else None
    for day in split_days(times, utc_offset_h, [o.el_deg for o in obs], lon):
        rej0 = kf.n_rejected
        for i in day.index:
            kf.update(obs[i])
        if kf.initialised:
            results.append(
                kf.day_result(
                    float(np.median(times[day.index])), day.date, int(day.index.size), kf.n_rejected - rej0
                )
            )
    return results, kf
