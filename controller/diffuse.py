"""When to leave the sun for the sky: the DIFFUSE mode's switch and orientation.

Under an overcast sky the beam is gone and the radiance is spread over the dome, so a
panel facing the zenith (seeing the whole sky) collects more than one facing the hidden
sun.  The switch classifies a rolling window of pyranometer samples
(:func:`controller.sky.classify_window`) and changes mode only with hysteresis: it enters
after a long window judged overcast, leaves as soon as a short window is not, and waits a
dwell time before entering again, so broken clouds do not make the drives hunt.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from .schema import setting
from .sky import SkyConfig, classify_window
from .sun.source import Site, solar_position


@dataclass(frozen=True, kw_only=True)
class DiffuseConfig:
    """The DIFFUSE mode: panels flat under an overcast sky, with hysteresis and dwell."""

    enabled: bool | None = setting(
        None, doc="Switch DIFFUSE on at all.", derived="true when a [pyranometer] is configured"
    )
    window_h: float = setting(
        2.0, doc="Overcast over this window (sun above 10 deg) enters DIFFUSE.", unit="h", ge=0.25, le=24
    )
    exit_window_h: float = setting(
        0.25, doc="Anything but overcast over this shorter window leaves DIFFUSE.", unit="h", ge=0.25, le=24
    )
    dwell_s: float = setting(
        900.0, doc="After leaving, the minimum time before entering again.", unit="s", ge=0, le=86400
    )
    method: Literal["default", "seed"] = setting("default", doc="Sky classifier rule (see docs/skytype.md).")
    min_elevation_deg: float = setting(
        10.0, doc="Only samples with the sun above this count.", unit="deg", ge=0, le=45
    )


class DiffuseSwitch:
    """Rolling-window sky classification with hysteresis and dwell."""

    def __init__(self, site: Site, config: DiffuseConfig | None = None):
        config = config if config is not None else DiffuseConfig()
        if config.enabled is None:  # built on its own (no [pyranometer] to decide): on
            config = replace(config, enabled=True)
        self.site = site
        self.config = config
        # Near sunrise and sunset the pyranometer's view of the sunshine is unreliable (and
        # low beam matters little): only the part of the window with the sun above
        # min_elevation_deg is classified, and it must fill most of the window.
        self.sky_config = SkyConfig(method=config.method, min_elevation_deg=config.min_elevation_deg)
        self.samples: deque[tuple[float, float]] = deque()
        self.active = False
        self.since = -np.inf
        self.last_class = 0

    def add(self, t: float, ghi_w_m2: float) -> None:
        self.samples.append((t, ghi_w_m2))
        horizon = t - max(self.config.window_h, self.config.exit_window_h) * 3600.0
        while self.samples and self.samples[0][0] < horizon:
            self.samples.popleft()

    def _classify(self, t: float, hours: float) -> int:
        if len(self.samples) < 10 or not self._sun_high(t - hours * 3600.0, t):
            return 0
        arr = np.asarray(self.samples)
        return classify_window(
            arr[:, 0],
            arr[:, 1],
            self.site,
            hours=hours,
            end=t,
            config=self.sky_config,
            min_daylight_s=hours * 3600 * 0.8,
        ).sky_class

    def _sun_high(self, t_start: float, t_end: float) -> bool:
        """The sun stays above ``min_elevation_deg`` over the whole window.

        Near the horizon a pyranometer cannot tell a clear sky from an overcast one (the
        beam share of a low sun is small either way), so such windows are not judged.
        Elevation has one maximum a day, so a window shorter than a day is above the
        threshold throughout when both its ends are.
        """
        el = solar_position(self.site, [t_start, t_end])["apparent_elevation"].to_numpy()
        return bool(np.all(el >= self.config.min_elevation_deg))

    def update(self, t: float) -> bool:
        """Decide at time ``t`` whether DIFFUSE applies; returns the new state.

        Entering needs the whole entry window overcast and, after a previous exit, the
        dwell time.  Leaving happens as soon as the short exit window is no longer
        overcast: the beam is worth far more than the diffuse gain, and re-entry needs a
        full overcast window again, so leaving early cannot make the drives hunt.
        """
        if not self.config.enabled:
            return False
        if not self.active:
            if t - self.since < self.config.dwell_s:
                return False
            self.last_class = self._classify(t, self.config.window_h)
            if self.last_class == 3:
                self.active, self.since = True, t
        else:
            self.last_class = self._classify(t, self.config.exit_window_h)
            if self.last_class in (1, 2):
                self.active, self.since = False, t
        return self.active
