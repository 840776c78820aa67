"""Build the configured sun source (and the camera sensor that feeds it).

The application layer's job: a camera source puts together a frame source, a sensor's
estimator with its calibration bundle and the sun-path filter, which ``controller.sun``
itself does not know about (it is a leaf package).  One builder per ``control.sun_source``.
"""

from __future__ import annotations

from collections.abc import Callable

from controller.config import Config
from controller.errors import ConfigError
from controller.sun.camera import CameraSunSensor, FolderFrameSource, FrameSource
from controller.sun.source import EphemerisSource, SunSource

Built = tuple[SunSource, CameraSunSensor | None]


def _ephemeris(config: Config, frames: FrameSource | None, now: float | None) -> Built:
    return EphemerisSource(config.site), None


def _hotspot(config: Config, frames: FrameSource | None, now: float | None) -> Built:
    from controller.calibration.bundle import load_bundle
    from controller.sunpath.policy import SunPathSource
    from controller.vision import HotspotEstimator

    hs = config.hotspot
    assert hs is not None  # the schema requires [hotspot] for this source
    if hs.frames == "hil":
        if frames is None:
            raise ConfigError(
                config.file, "hotspot.frames", "a folder or device:N outside the simulator", hs.frames
            )
    elif hs.frames.startswith("device:"):
        raise ConfigError(
            config.file,
            "hotspot.frames",
            "a folder of timestamped images (live devices are not supported yet)",
            hs.frames,
        )
    else:
        frames = FolderFrameSource(hs.frames)
    estimator = HotspotEstimator(load_bundle(hs.calibration), algorithm=hs.algorithm)
    source = SunPathSource(
        config.site if config.sunpath.site_known else None, state_path=config.sunpath.state, now=now
    )
    return source, CameraSunSensor(frames, estimator)


#: ``control.sun_source`` -> builder(config, frames from the simulator or None, the present).
BUILDERS: dict[str, Callable[[Config, FrameSource | None, float | None], Built]] = {
    "ephemeris": _ephemeris,
    "hotspot": _hotspot,
}


def build_sun_source(config: Config, frames: FrameSource | None = None, now: float | None = None) -> Built:
    """(sun source, camera sensor or None) for ``config.control.sun_source``.

    ``frames`` supplies images when a camera's ``frames = "hil"`` (the simulator's renderer);
    ``now`` is the present on the controller's clock (POSIX s; default the wall clock): a
    learned state from its future is refused.
    """
    return BUILDERS[config.control.sun_source](config, frames, now)
