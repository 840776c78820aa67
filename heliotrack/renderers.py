"""Which renderer of the world draws the frames of which camera sensor: the one place.

``simulate`` feeds the controller's camera from here, ``hil record`` writes the same frames
to disk, so a recorded day replays into what the live simulation saw.  A new camera sensor
(a fisheye sky camera, ...) adds one entry to :data:`RENDERERS`: a function that takes the
scenario and the clouds' beam transmittance at a time and returns ``render(t) -> image``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from controller.config import Config

from .scenario import ScenarioConfig

if TYPE_CHECKING:
    from hil.skycam import CloudField

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


def cloud_layer(config: ScenarioConfig) -> CloudField | None:
    """The procedural cloud layer every sky-looking camera of the scenario draws (the sky
    camera, the panel cameras): none when every day is clear, a deck when every day is
    overcast, else broken cumulus.  The sun's own dimming follows the scenario's beam
    transmittance, not this layer (as for the hotspot camera)."""
    from hil.skycam import CloudField

    kinds = set(config.hil.skies)
    if kinds == {"clear"}:
        return None
    return CloudField(coverage=1.0, tau_max=20.0) if kinds == {"overcast"} else CloudField(coverage=0.45)


def _fisheye(config: ScenarioConfig, transmittance: Transmittance) -> Render:
    """The sky camera (``hil/skycam``) at the scenario's site, with a procedural cloud layer
    on cloudy days whose sun is dimmed by the scenario's own beam transmittance (so a cloud
    that hides the sun from the world hides it from every camera)."""
    from hil.camera import Site as CameraSite
    from hil.skycam import orientation, render_sky, sky_profile

    site, cam = config.site, config.hil.skycam
    clouds = cloud_layer(config) if cam.clouds else None
    scn = sky_profile(
        cam.profile,
        noise=cam.noise,
        site=CameraSite(site.latitude, site.longitude, site.altitude),
        enu_from_camera=orientation(
            yaw_deg=cam.yaw_deg, tilt_deg=cam.tilt_deg, tilt_azimuth_deg=cam.tilt_azimuth_deg
        ),
        clouds=clouds,
    )

    def render(t: float) -> np.ndarray:
        beam = min(max(transmittance(t), 0.0), 1.0)
        return render_sky(scn, t, sun_transmittance=beam).image

    return render


#: ``control.sun_source`` of a camera sensor -> the world's renderer of its frames.
RENDERERS: dict[str, Callable[[ScenarioConfig, Transmittance], Render]] = {"hotspot": _hotspot}
RENDERERS["fisheye"] = _fisheye
#: ``control.sun_source`` of several cameras fused -> their sensors (each in RENDERERS).
FUSED: dict[str, tuple[str, ...]] = {"fused": ("hotspot", "fisheye")}


def camera_sensors(config: Config) -> tuple[str, ...]:
    """Every camera sensor the controller looks through (both when fused), in order."""
    source = config.control.sun_source
    return FUSED.get(source, (source,) if source in RENDERERS else ())


def world_renderers(config: ScenarioConfig, transmittance: Transmittance) -> dict[str, Render]:
    """The world's renderer of every configured camera whose ``frames = "hil"``, by name."""
    out: dict[str, Render] = {}
    for name in camera_sensors(config):
        if getattr(getattr(config, name, None), "frames", None) == "hil":
            out[name] = RENDERERS[name](config, transmittance)
    return out


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
