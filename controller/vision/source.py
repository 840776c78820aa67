"""The hotspot sensor as a :class:`~controller.sun.source.SunSource`.

``frames`` is any callable ``t -> uint8 image or None`` (a camera, a frame folder, or, in the
loop, the HIL renderer wrapped by the CLI: ``lambda t: render_frame(scn, t).image``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..sun.source import SunSource
from ..sun.types import EstimateSource, SunEstimate
from .estimator import HotspotEstimator, HotspotResult


class HotspotSunSource(SunSource):
    name = "hotspot"

    def __init__(self, estimator: HotspotEstimator, frames: Callable[[float], np.ndarray | None]):
        self.estimator = estimator
        self.frames = frames
        self.last: HotspotResult | None = None

    def observe(self, t: float) -> HotspotResult | None:
        img = self.frames(t)
        if img is None:
            self.last = None
            return None
        self.last = self.estimator.estimate_image(img, t)
        return self.last

    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        """ENU estimate from the frame at ``t``; None without a glint or without levelling
        and azimuth alignment (a model-frame direction cannot steer a tracker)."""
        r = self.observe(t)
        if r is None or not r.found or r.frame != "enu":
            return None
        s2 = float(r.sigma_deg) ** 2
        c = max(np.cos(np.radians(r.el_deg)), 1e-3)
        return SunEstimate(time=float(t), az_deg=float(r.az_deg), el_deg=float(r.el_deg),
                           covariance=np.diag([s2 / (c * c), s2]), source=EstimateSource.OBSERVED)
