"""Vision: the fisheye sky camera's sun sensor (paper 003).

API::

    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.vision.fisheye import FisheyeEstimator, SeedEstimator
    est = FisheyeEstimator(load_fisheye_bundle("sky.toml"))   # or SeedEstimator (the paper's)
    res = est.estimate_image(image_bgr, t, prior=None)         # FisheyeResult
    obs = res.observation()                                    # SunObservation or None

Frames of one sequence go through one estimator (the previous accepted detection gates the
next); ``reset_sequence()`` starts another.  See docs/fisheye.md.
"""

from .channel import glare_channel
from .default import FisheyeEstimator, FisheyeOptions
from .frames import as_bgr8, load_frame
from .glare import GlareOptions
from .lens import FisheyeLens
from .result import FisheyeResult
from .seed import SeedEstimator

__all__ = [
    "FisheyeEstimator",
    "FisheyeLens",
    "FisheyeOptions",
    "FisheyeResult",
    "GlareOptions",
    "SeedEstimator",
    "as_bgr8",
    "glare_channel",
    "load_frame",
]
