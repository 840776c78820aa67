"""HIL sky camera: whole-sky images through a Kannala-Brandt fisheye (paper 003's sensor).

Main entry points::

    from hil.skycam import sky_profile, render_sky
    scn = sky_profile("seed")                 # or "hd"; noise=False for the ideal camera
    frame = render_sky(scn, t)               # frame.image (BGR uint8), frame.truth (dict)

The world never imports the controller: the lens model, its inverse and every direction
here are computed independently of the controller's OpenCV-based code.
"""

from .clouds import CloudField
from .distractors import AircraftGlint, FlareGhost, SpecularReflection
from .lens import FisheyeLens, full_hd_lens, hd_lens, seed_lens
from .render import SkyFrame, render_sky
from .scene import PROFILES, SITES, SkyScene, SkySensor, orientation, sky_profile, sun_position
from .sky import SkyModel
from .sun import GlareModel

__all__ = [
    "PROFILES",
    "SITES",
    "AircraftGlint",
    "CloudField",
    "FisheyeLens",
    "FlareGhost",
    "GlareModel",
    "SkyFrame",
    "SkyModel",
    "SkyScene",
    "SkySensor",
    "SpecularReflection",
    "full_hd_lens",
    "hd_lens",
    "orientation",
    "render_sky",
    "seed_lens",
    "sky_profile",
    "sun_position",
]
