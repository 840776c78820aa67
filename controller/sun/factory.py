"""Build the configured sun source (and the camera sensor that feeds it)."""

from __future__ import annotations

from ..config import Config
from ..errors import ConfigError
from .camera import CameraSunSensor, FolderFrameSource, FrameSource
from .source import EphemerisSource, SunSource


def build_sun_source(config: Config, frames: FrameSource | None = None
                     ) -> tuple[SunSource, CameraSunSensor | None]:
    """(sun source, camera sensor or None) for ``config.control.sun_source``.

    ``frames`` supplies images when ``[hotspot] frames = "hil"`` (the simulator's renderer).
    """
    if config.control.sun_source == "ephemeris":
        return EphemerisSource(config.site), None
    from ..calibration.bundle import load_bundle
    from ..sunpath.policy import SunPathSource
    from ..vision import HotspotEstimator

    hs = config.hotspot
    if hs.frames == "hil":
        if frames is None:
            raise ConfigError(config.file, "hotspot.frames",
                              "a folder or device:N outside the simulator", hs.frames)
    elif hs.frames.startswith("device:"):
        raise ConfigError(config.file, "hotspot.frames",
                          "a folder of timestamped images (live devices are not supported yet)",
                          hs.frames)
    else:
        frames = FolderFrameSource(hs.frames)
    estimator = HotspotEstimator(load_bundle(hs.calibration), algorithm=hs.algorithm)
    source = SunPathSource(config.site if config.sunpath.site_known else None,
                           state_path=config.sunpath.state)
    return source, CameraSunSensor(frames, estimator)
