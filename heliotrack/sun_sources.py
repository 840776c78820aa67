"""Build the configured sun source (and the camera sensor that feeds it).

The application layer's job: a camera source puts together a frame source, a sensor's
estimator with its calibration bundle and the sun-path filter, which ``controller.sun``
itself does not know about (it is a leaf package).  One builder per ``control.sun_source``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from controller.clock import Clock
from controller.config import Config
from controller.errors import ConfigError
from controller.sun.camera import (
    CameraSunSensor,
    FolderFrameSource,
    FrameSource,
    VideoCaptureFrameSource,
)
from controller.sun.source import EphemerisSource, SunSource

Built = tuple[SunSource, CameraSunSensor | None]
Builder = Callable[[Config, FrameSource | None, float | None, Clock | None], Built]


def open_frame_source(spec: str, clock: Clock | None = None) -> FrameSource:
    """The camera of ``[hotspot] frames``: ``device:N`` (OpenCV camera N), a stream URL
    (``rtsp://``, ``http://``), a video file (played on ``clock`` from now), or a folder of
    timestamped images (watched for new ones).

    Raises
    ------
    ConfigError
        ``"hil"`` (the simulator's renderer), or nothing usable at that path.
    """
    if spec == "hil":
        raise ConfigError(
            None, "hotspot.frames", 'a camera outside the simulator ("hil" is its renderer)', spec
        )
    if spec.startswith("device:") or "://" in spec:
        return VideoCaptureFrameSource(spec, clock)
    path = Path(spec)
    if path.is_dir():
        return FolderFrameSource(path)
    if path.is_file():
        return VideoCaptureFrameSource(spec, clock)
    raise ConfigError(
        None, "hotspot.frames", "a folder of timestamped images, a video file, device:N or a URL", spec
    )


def _ephemeris(config: Config, frames: FrameSource | None, now: float | None, clock: Clock | None) -> Built:
    return EphemerisSource(config.site), None


def _hotspot(config: Config, frames: FrameSource | None, now: float | None, clock: Clock | None) -> Built:
    from controller.calibration.bundle import load_bundle
    from controller.sunpath.policy import SunPathSource
    from controller.vision import HotspotEstimator

    hs = config.hotspot
    assert hs is not None  # the schema requires [hotspot] for this source
    if hs.frames != "hil":
        frames = open_frame_source(hs.frames, clock)
    elif frames is None:
        raise ConfigError(
            config.file,
            "hotspot.frames",
            "a folder, a video file, device:N or a URL outside the simulator",
            hs.frames,
        )
    try:
        estimator = HotspotEstimator(load_bundle(hs.calibration), algorithm=hs.algorithm)
        source = SunPathSource(
            config.site if config.sunpath.site_known else None, state_path=config.sunpath.state, now=now
        )
    except BaseException:
        frames.close()
        raise
    return source, CameraSunSensor(frames, estimator)


#: ``control.sun_source`` -> builder(config, frames from the simulator or None, the present,
#: the clock a live camera stamps its frames with).
BUILDERS: dict[str, Builder] = {
    "ephemeris": _ephemeris,
    "hotspot": _hotspot,
}


def build_sun_source(
    config: Config, frames: FrameSource | None = None, now: float | None = None, clock: Clock | None = None
) -> Built:
    """(sun source, camera sensor or None) for ``config.control.sun_source``.

    ``frames`` supplies images when a camera's ``frames = "hil"`` (the simulator's renderer);
    any other ``frames`` is opened here (:func:`open_frame_source`, on ``clock``, default
    the wall clock).  ``now`` is the present on the controller's clock (POSIX s; default
    the wall clock): a learned state from its future is refused.
    """
    return BUILDERS[config.control.sun_source](config, frames, now, clock)
