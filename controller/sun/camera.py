"""Camera sun sensors in the loop: where frames come from, and turning them into observations.

A :class:`FrameSource` hands out the latest frame at a time: a live device (OpenCV
``VideoCapture``), a folder of timestamped images (replay), or any callable (the HIL
renderer, wired in by the application layer, so the controller never imports the world).
:class:`CameraSunSensor` runs an estimator on each frame and keeps count of why frames
gave nothing.
"""

from __future__ import annotations

import abc
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..timestamps import CANONICAL_EXAMPLE, time_from_name
from ..vision.imageio import read_image
from .types import SunObservation

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm"}


@dataclass(frozen=True)
class CameraFrame:
    image: np.ndarray
    time: float  # POSIX s when it was exposed
    name: str = ""


class FrameSource(abc.ABC):
    @abc.abstractmethod
    def grab(self, t: float) -> CameraFrame | None:
        """The newest frame exposed at or before ``t`` (None when there is none)."""


class CallableFrameSource(FrameSource):
    """Frames from ``render(t) -> image`` (the HIL renderer)."""

    def __init__(self, render: Callable[[float], np.ndarray]):
        self.render = render

    def grab(self, t: float) -> CameraFrame | None:
        return CameraFrame(self.render(t), float(t), "rendered")


class FolderFrameSource(FrameSource):
    """Replay a folder of images whose names carry ISO timestamps.

    ``grab(t)`` returns the newest frame not later than ``t`` and not older than
    ``max_age_s``.  Files without a timestamp are refused at start with their names.
    """

    def __init__(self, folder: str | Path, max_age_s: float = 120.0):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise ConfigError(None, "hotspot.frames", "a folder of timestamped images", str(folder))
        files = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        stamped = [(time_from_name(p.name), p) for p in files]
        bad = [p.name for ts, p in stamped if ts is None]
        if bad:
            raise ConfigError(
                None,
                "hotspot.frames",
                f"image names with a timestamp (e.g. {CANONICAL_EXAMPLE}.png)",
                ", ".join(bad[:3]) + (" ..." if len(bad) > 3 else ""),
            )
        self.frames = sorted((ts, p) for ts, p in stamped)
        self.times = np.array([ts for ts, _ in self.frames])
        self.max_age_s = max_age_s

    def grab(self, t: float) -> CameraFrame | None:
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i < 0 or t - self.times[i] > self.max_age_s:
            return None
        ts, path = self.frames[i]
        img, _ = read_image(path)
        if img is None:  # unreadable, truncated or oversized: the estimator is not fed junk
            return None
        return CameraFrame(img, ts, path.name)


class CameraSunSensor:
    """Frames -> :class:`SunObservation` with an estimator exposing
    ``estimate_image(image, t)`` whose result has ``observation()``."""

    def __init__(self, frames: FrameSource, estimator, name: str = "hotspot"):
        self.frames = frames
        self.estimator = estimator
        self.name = name
        self.outcomes: Counter[str] = Counter()

    def observe(self, t: float) -> SunObservation | None:
        frame = self.frames.grab(t)
        if frame is None:
            self.outcomes["no frame"] += 1
            return None
        result = self.estimator.estimate_image(frame.image, frame.time)
        obs = result.observation()
        if obs is None:
            self.outcomes[getattr(result, "reason", "") or "not found"] += 1
        else:
            self.outcomes["found"] += 1
        return obs
