"""Daylight that the configured site and clock do not see, from the pyranometer, live.

A plant whose sun source is the ephemeris has nothing else to tell a wrong site from a
right one: with the longitude's sign flipped at 48 deg E, the sun is computed 6.4 h late,
the plant stows through the morning and tracks into the night, and no check fires.  A
pyranometer settles it: light while the sun is computed well below the horizon cannot be
(twilight gives a few W/m2 there).  The thresholds are :mod:`.plausibility`'s ``night``
check for a record (the same mistakes, seen by ``classify`` after the fact); here they are
judged over a rolling day, so the alarm comes within the first 20 min of lit night.

Angles in degrees, times in POSIX seconds (UTC), irradiance in W/m2.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from .plausibility import NIGHT_ELEVATION_DEG, NIGHT_GHI_W_M2
from .solar import cos_zenith_rows, row_geometry

if TYPE_CHECKING:
    from controller.sun.source import Site

#: A sample counts for the time since the one before, but never for more than this (s): a
#: gap in the readings is not light.
MAX_SAMPLE_S = 300.0
#: Lit night is summed over this window (s).
WINDOW_S = 86400.0
#: Lit night in the window that raises the alarm (s).  A clock an hour off, at 32 deg N in
#: March, gives 28 min of it at one edge of the day (the sun climbs 12.6 deg an hour there,
#: and clear-sky GHI passes 20 W/m2 about 2 deg up); true twilight gives none.
LIT_NIGHT_ALARM_S = 1200.0


def elevation_deg(site: Site, t: float) -> float:
    """The sun's geometric elevation at ``site`` and POSIX time ``t`` (deg, to about 0.5: the
    declination is the day's, and refraction, which only lifts the sun near the horizon, is
    left out)."""
    cz = cos_zenith_rows(np.array([t]), 60.0, 1, site.latitude, site.longitude, row_geometry(np.array([t])))
    return float(np.degrees(np.arcsin(np.clip(cz[0, 0], -1.0, 1.0))))


class DaylightCheck:
    """Light at computed night, summed over the last day; an alarm from 20 min of it.

    Parameters
    ----------
    site : Site
        The configured site.
    """

    def __init__(self, site: Site):
        self.site = site
        self.lit: deque[tuple[float, float]] = deque()  # (time, seconds it counts for)
        self.last_t: float | None = None
        self.worst: tuple[float, float] = (0.0, 0.0)  # (GHI, computed elevation) of the brightest
        self.alarm = ""

    def add(self, t: float, ghi_w_m2: float) -> str:
        """Take one valid pyranometer sample; return the alarm's text ("" when none)."""
        dt = 0.0 if self.last_t is None else min(max(t - self.last_t, 0.0), MAX_SAMPLE_S)
        self.last_t = t
        while self.lit and self.lit[0][0] < t - WINDOW_S:
            self.lit.popleft()
        if ghi_w_m2 > NIGHT_GHI_W_M2:
            el = elevation_deg(self.site, t)
            if el < NIGHT_ELEVATION_DEG:
                self.lit.append((t, dt))
                if ghi_w_m2 > self.worst[0]:
                    self.worst = (ghi_w_m2, el)
        seconds = sum(d for _, d in self.lit)
        if seconds >= LIT_NIGHT_ALARM_S:
            ghi, el = self.worst
            self.alarm = (
                f"daylight while the sun is computed below the horizon ({seconds / 60:.0f} min in the "
                f"last day, up to {ghi:.0f} W/m2 with the sun computed at {el:.1f} deg): check the site's "
                f"longitude and latitude signs (east and north positive) and the clock, or the "
                f"pyranometer's reading"
            )
        elif not self.lit:
            self.alarm, self.worst = "", (0.0, 0.0)
        return self.alarm
