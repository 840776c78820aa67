"""Vision: the hotspot (convex-surface) sun sensor's estimator.

API for the loop::

    from controller.calibration.bundle import load_bundle
    from controller.vision import HotspotEstimator
    est = HotspotEstimator(load_bundle("config/calibration/recommended.toml"))
    res = est.estimate_image(image_uint8, t)     # HotspotResult
    obs = res.observation()                      # SunObservation or None

In the control loop, :class:`controller.sun.camera.CameraSunSensor` runs the estimator on
each frame and feeds the sun-path filter (built by `heliotrack.sun_sources`).
"""

from .estimator import HotspotEstimator
from .hotspot import segment_fast, segment_seed
from .mirror import level_rotation, mirror_sun_direction
from .result import HotspotResult

__all__ = [
    "HotspotEstimator",
    "HotspotResult",
    "mirror_sun_direction",
    "level_rotation",
    "segment_fast",
    "segment_seed",
]
