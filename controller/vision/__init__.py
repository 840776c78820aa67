"""Vision: the hotspot (convex-surface) sun sensor's estimator.

API for the loop::

    from controller.calibration.bundle import load_bundle
    from controller.vision import HotspotEstimator
    est = HotspotEstimator(load_bundle("config/calibration/recommended.toml"))
    res = est.estimate_image(image_uint8, t)     # HotspotResult
    obs = res.observation()                      # SunObservation or None
    src = HotspotSunSource(est, frames=lambda t: image_at(t))   # a SunSource
"""

from .estimator import HotspotEstimator, HotspotResult, level_rotation, mirror_sun_direction
from .hotspot import segment_fast, segment_seed
from .source import HotspotSunSource

__all__ = ["HotspotEstimator", "HotspotResult", "mirror_sun_direction", "level_rotation",
           "segment_fast", "segment_seed", "HotspotSunSource"]
