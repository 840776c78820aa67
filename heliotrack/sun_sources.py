"""Build the configured sun source (and the camera sensor that feeds it).

The application layer's job: a camera source puts together a frame source, a sensor's
estimator with its calibration bundle and the sun-path filter, which ``controller.sun``
itself does not know about (it is a leaf package).  One builder per ``control.sun_source``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
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
from controller.sun.cameras import CameraGroup
from controller.sun.source import EphemerisSource, SunSource

#: The simulator's frames: one source (the configured camera's) or one per camera name.
Frames = FrameSource | Mapping[str, FrameSource] | None
Built = tuple[SunSource, CameraSunSensor | CameraGroup | None]
Builder = Callable[[Config, Frames, float | None, Clock | None], Built]

log = logging.getLogger(__name__)


def open_frame_source(spec: str, clock: Clock | None = None, key: str = "hotspot.frames") -> FrameSource:
    """The camera of ``[hotspot] frames`` (or ``[fisheye] frames``; ``key`` names it in
    errors): ``device:N`` (OpenCV camera N), a stream URL (``rtsp://``, ``http://``), a
    video file (played on ``clock`` from now), or a folder of timestamped images (watched
    for new ones).

    Raises
    ------
    ConfigError
        ``"hil"`` (the simulator's renderer), or nothing usable at that path.
    """
    if spec == "hil":
        raise ConfigError(None, key, 'a camera outside the simulator ("hil" is its renderer)', spec)
    if spec.startswith("device:") or "://" in spec:
        return VideoCaptureFrameSource(spec, clock)
    path = Path(spec)
    if path.is_dir():
        return FolderFrameSource(path)
    if path.is_file():
        return VideoCaptureFrameSource(spec, clock)
    raise ConfigError(None, key, "a folder of timestamped images, a video file, device:N or a URL", spec)


def _ephemeris(config: Config, frames: Frames, now: float | None, clock: Clock | None) -> Built:
    return EphemerisSource(config.site), None


def _sun_path(config: Config, now: float | None):
    from controller.sunpath.policy import SunPathSource

    return SunPathSource(
        config.site if config.sunpath.site_known else None, state_path=config.sunpath.state, now=now
    )


def _camera(config: Config, name: str, frames: Frames, clock: Clock | None, sun) -> CameraSunSensor:
    """The camera sensor of table ``[name]`` (``hotspot`` or ``fisheye``): its frames (the
    simulator's when ``frames = "hil"``), its estimator on its bundle; the fisheye's
    estimator gets the sun-path filter's prediction as its prior."""
    table = getattr(config, name)
    assert table is not None  # the schema requires the table for this source
    if table.frames != "hil":
        source = open_frame_source(table.frames, clock, f"{name}.frames")
    else:
        given = frames.get(name) if isinstance(frames, Mapping) else frames
        if given is None:
            raise ConfigError(
                config.file,
                f"{name}.frames",
                "a folder, a video file, device:N or a URL outside the simulator",
                table.frames,
            )
        source = given
    try:
        if name == "fisheye":
            from controller.calibration.fisheye_bundle import load_fisheye_bundle
            from controller.vision.fisheye import FisheyeEstimator, SeedEstimator

            bundle = plant_site_bundle(config, load_fisheye_bundle(table.calibration))
            fe = SeedEstimator(bundle) if table.algorithm == "seed" else FisheyeEstimator(bundle)
            prior = getattr(sun, "prediction", None)
            return CameraSunSensor(source, fe, name, interval_s=table.interval_s, colour=True, prior=prior)
        from controller.calibration.bundle import load_bundle
        from controller.vision import HotspotEstimator

        estimator = HotspotEstimator(load_bundle(table.calibration), algorithm=table.algorithm)
        return CameraSunSensor(source, estimator, name, interval_s=table.interval_s)
    except BaseException:
        source.close()
        raise


#: A fisheye bundle's [site] further than this (deg) from the plant's is said.
SITE_TOLERANCE_DEG = 0.05


def plant_site_bundle(config: Config, bundle):
    """The fisheye bundle with the plant's ``[site]`` for its ephemeris gate, when the plant's
    site is known (``sunpath.site_known``): the plant file is where the site is set.  A
    bundle calibrated elsewhere (the shipped one, at Andimeshk) had put the gate there, and
    at another site the loop's sky camera refused every frame (0 of 639 at Cape Town,
    reading the ephemeris instead, without a word).  A bundle's own site over 0.05 deg away
    is said once."""
    from dataclasses import replace

    from controller.calibration.fisheye_bundle import SiteCal

    if not config.sunpath.site_known:
        return bundle  # the site is learned: the bundle's, if any, stays the camera's own
    site = config.site
    own = bundle.site
    if own is not None and max(abs(own.latitude - site.latitude), abs(own.longitude - site.longitude)) > (
        SITE_TOLERANCE_DEG
    ):
        log.warning(
            "%s: [site] %.4f, %.4f is not the plant's %.4f, %.4f: the plant's is used for the "
            "fisheye's ephemeris gate (a bundle calibrated elsewhere? calibrate its orientation "
            "on site: heliotrack calibrate fisheye orientation)",
            bundle.path,
            own.latitude,
            own.longitude,
            site.latitude,
            site.longitude,
        )
    return replace(
        bundle, site=SiteCal(latitude=site.latitude, longitude=site.longitude, altitude=site.altitude)
    )


def _cameras(*names: str) -> Builder:
    """The builder of a sun-path filter fed by the cameras ``names`` (a group when several)."""

    def build(config: Config, frames: Frames, now: float | None, clock: Clock | None) -> Built:
        source = _sun_path(config, now)
        sensors: list[CameraSunSensor] = []
        try:
            for name in names:
                sensors.append(_camera(config, name, frames, clock, source))
        except BaseException:
            for s in sensors:
                s.close()
            raise
        return source, sensors[0] if len(sensors) == 1 else CameraGroup(sensors)

    return build


#: ``control.sun_source`` -> builder(config, frames from the simulator or None, the present,
#: the clock a live camera stamps its frames with).
BUILDERS: dict[str, Builder] = {
    "ephemeris": _ephemeris,
    "hotspot": _cameras("hotspot"),
    "fisheye": _cameras("fisheye"),
    "fused": _cameras("hotspot", "fisheye"),
}


def build_sun_source(
    config: Config, frames: Frames = None, now: float | None = None, clock: Clock | None = None
) -> Built:
    """(sun source, camera sensor, group of sensors or None) for ``config.control.sun_source``.

    ``frames`` supplies images when a camera's ``frames = "hil"`` (the simulator's renderer:
    one source, or a mapping camera name -> source when both cameras are fused);
    any other ``frames`` is opened here (:func:`open_frame_source`, on ``clock``, default
    the wall clock).  ``now`` is the present on the controller's clock (POSIX s; default
    the wall clock): a learned state from its future is refused.
    """
    return BUILDERS[config.control.sun_source](config, frames, now, clock)
