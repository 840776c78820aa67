"""Which renderer of the world draws the frames of which camera sensor: the one place.

``simulate`` feeds the controller's camera from here, ``hil record`` writes the same frames
to disk, so a recorded day replays into what the live simulation saw.  A new camera sensor
(a fisheye sky camera, ...) adds one entry to :data:`RENDERERS`: a function that takes the
scenario and the clouds' beam transmittance at a time and returns ``render(t) -> image``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from controller.config import Config

from .scenario import ScenarioConfig

#: render(t) -> image (uint8, grey or BGR), t in POSIX s.
Render = Callable[[float], np.ndarray]
#: beam_transmittance(t) in 0..1: the clouds over the sun at t (1: sun free).
Transmittance = Callable[[float], float]


def _hotspot(config: ScenarioConfig, transmittance: Transmittance) -> Render:
    from hil.camera import Site as CameraSite
    from hil.camera import profile, render_frame

    site = config.site
    cam = config.hil.camera
    scn = profile(cam.profile, noise=cam.noise, tilt_deg=cam.tilt_deg).with_(
        site=CameraSite(site.latitude, site.longitude, site.altitude)
    )

    def render(t: float) -> np.ndarray:
        return render_frame(scn, t, transmittance=transmittance(t)).image

    return render


#: ``control.sun_source`` of a camera sensor -> the world's renderer of its frames.
RENDERERS: dict[str, Callable[[ScenarioConfig, Transmittance], Render]] = {"hotspot": _hotspot}


def camera_sensor(config: Config) -> str | None:
    """The camera sensor the controller looks through (``control.sun_source``), or None."""
    source = config.control.sun_source
    return source if source in RENDERERS else None


def frames_setting(config: Config) -> str | None:
    """The configured camera's ``frames`` ("hil", a folder, "device:N"), or None."""
    sensor = camera_sensor(config)
    table = getattr(config, sensor, None) if sensor else None
    return getattr(table, "frames", None)


def frame_interval_s(config: Config) -> float:
    """Time between the frames the controller reads (its ``interval_s``; 0: every cycle)."""
    sensor = camera_sensor(config)
    table = getattr(config, sensor, None) if sensor else None
    interval = float(getattr(table, "interval_s", 0.0) or 0.0)
    return interval if interval > 0 else config.control.period_s


def world_renderer(config: ScenarioConfig, transmittance: Transmittance) -> Render | None:
    """The world's renderer of the configured camera, or None without a camera sensor."""
    sensor = camera_sensor(config)
    return RENDERERS[sensor](config, transmittance) if sensor else None
