"""HIL camera: renderer of the convex-surface (hotspot) sun sensor and its calibration views.

Main entry points::

    from hil.camera import profile, render_frame
    scn = profile("recommended")            # or "seed"; noise=False for the ideal camera
    frame = render_frame(scn, t)           # frame.image (uint8), frame.truth (dict)

The world never imports the controller.
"""

from .camera import CameraModel, Pose
from .render import Frame, render_frame
from .scene import PROFILES, Base, Globe, Scenario, Sensor, Site, profile
from .views import checkerboard_poses, render_checkerboard, render_marker_view, render_plumb_view

__all__ = [
    "CameraModel",
    "Pose",
    "Frame",
    "render_frame",
    "render_checkerboard",
    "checkerboard_poses",
    "render_marker_view",
    "render_plumb_view",
    "PROFILES",
    "Base",
    "Globe",
    "Scenario",
    "Sensor",
    "Site",
    "profile",
]
