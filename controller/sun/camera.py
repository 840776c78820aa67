"""Camera sun sensors in the loop: where frames come from, and turning them into observations.

A :class:`FrameSource` hands out the latest frame at a time: a live camera or stream, or a
video file (:class:`VideoCaptureFrameSource`, OpenCV ``VideoCapture``), a folder of
timestamped images that may grow while the controller runs (:class:`FolderFrameSource`),
or any callable (the HIL renderer, wired in by the application layer, so the controller
never imports the world).  :class:`CameraSunSensor` judges each frame, runs an estimator
on it and keeps count of why frames gave nothing.
"""

from __future__ import annotations

import abc
import logging
import math
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..clock import Clock, RealClock
from ..errors import ConfigError
from ..timestamps import CANONICAL_EXAMPLE, time_from_name
from ..vision.imageio import read_image
from .mount_watch import MountWatch
from .types import SunObservation

log = logging.getLogger("heliotrack.camera")

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

    def first_frame(self, t: float, timeout_s: float = 5.0) -> CameraFrame | None:
        """A frame for a one-off look (``heliotrack check``): a live source waits up to
        ``timeout_s`` for one; a recorded one gives its newest frame at ``t``."""
        return self.grab(t)

    def close(self) -> None:  # noqa: B027 - optional: most sources hold nothing open
        """Release the camera (a no-op for sources that hold nothing open)."""


def judge_frame(image: np.ndarray) -> str | None:
    """Why a frame cannot show a sun, before any estimator looks at it: ``black_frame`` (a
    dead sensor, a lens cap), ``saturated_frame`` (a blinded sensor), or None."""
    if image.size == 0:
        return "empty_frame"
    hi = float(np.percentile(image, 99.9)) if image.size > 1000 else float(image.max())
    if hi < 8.0:
        return "black_frame"
    if float(np.percentile(image, 5)) >= 250.0:
        return "saturated_frame"
    return None


def grey8(image: np.ndarray) -> np.ndarray | None:
    """An 8-bit single-channel copy of a frame as OpenCV delivers it (BGR, BGRA; 16-bit or
    float samples read as :func:`controller.vision.imageio.to_uint8` reads them)."""
    from ..vision.imageio import to_uint8

    image8, _ = to_uint8(image)
    if image8 is None:
        return None
    if image8.ndim == 3 and image8.shape[2] in (3, 4):
        code = cv2.COLOR_BGRA2GRAY if image8.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image8 = cv2.cvtColor(image8, code)
    if image8.ndim != 2:
        return None
    return np.ascontiguousarray(image8)


class CallableFrameSource(FrameSource):
    """Frames from ``render(t) -> image`` (the HIL renderer)."""

    def __init__(self, render: Callable[[float], np.ndarray]):
        self.render = render

    def grab(self, t: float) -> CameraFrame | None:
        return CameraFrame(self.render(t), float(t), "rendered")


class FolderFrameSource(FrameSource):
    """Frames from a folder of images whose names carry ISO timestamps.

    ``grab(t)`` returns the newest frame not later than ``t`` and not older than
    ``max_age_s``.  The folder is watched: images added after start (a camera or an FTP
    upload writing into it) are seen at the next grab, since the folder's modification
    time moves.  Files without a timestamp are refused at start with their names; one
    added later is skipped with a warning.  A file still being written reads as no frame
    until it is complete.
    """

    def __init__(self, folder: str | Path, max_age_s: float = 120.0):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise ConfigError(None, "hotspot.frames", "a folder of timestamped images", str(folder))
        self.max_age_s = max_age_s
        self._mtime_ns = -1
        self._skipped: set[str] = set()
        self._twins: set[tuple[str, str]] = set()
        bad = self._scan()
        if bad:
            raise ConfigError(
                None,
                "hotspot.frames",
                f"image names with a timestamp (e.g. {CANONICAL_EXAMPLE}.png, years 1900-2200)",
                ", ".join(bad[:3]) + (" ..." if len(bad) > 3 else ""),
            )

    def _scan(self) -> list[str]:
        """List the folder again; returns the names without a timestamp."""
        try:
            self._mtime_ns = self.folder.stat().st_mtime_ns
            files = [p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]
        except OSError as exc:
            log.warning("frame folder %s: %s", self.folder, exc)
            files = []
        stamped = [(time_from_name(p.name), p) for p in files]
        bad = sorted(p.name for ts, p in stamped if ts is None)
        self.frames = sorted((ts, p) for ts, p in stamped if ts is not None)
        for (t0, p0), (t1, p1) in zip(self.frames, self.frames[1:], strict=False):
            if t0 == t1 and (p0.name, p1.name) not in self._twins:  # say so once per pair
                self._twins.add((p0.name, p1.name))
                log.warning(
                    "frame folder %s: %s and %s name the same time; %s is used",
                    self.folder,
                    p0.name,
                    p1.name,
                    p1.name,
                )
        self.times = np.array([ts for ts, _ in self.frames])
        return bad

    def _refresh(self) -> None:
        try:
            mtime = self.folder.stat().st_mtime_ns
        except OSError:
            mtime = -2
        if mtime == self._mtime_ns:
            return
        for name in self._scan():
            if name not in self._skipped:
                self._skipped.add(name)
                log.warning("frame folder %s: %s has no timestamp in its name: skipped", self.folder, name)

    def grab(self, t: float) -> CameraFrame | None:
        self._refresh()
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i < 0 or t - self.times[i] > self.max_age_s:
            return None
        ts, path = self.frames[i]
        img, _ = read_image(path)
        if img is None:  # unreadable, truncated or oversized: the estimator is not fed junk
            return None
        return CameraFrame(img, ts, path.name)

    def first_frame(self, t: float, timeout_s: float = 5.0) -> CameraFrame | None:
        """The newest frame of the folder, however old."""
        self._refresh()
        for ts, path in reversed(self.frames):
            img, _ = read_image(path)
            if img is not None:
                return CameraFrame(img, ts, path.name)
        return None


def capture_target(spec: str) -> tuple[int | str, bool]:
    """``[hotspot] frames`` as OpenCV opens it: (device index or URL or path, live?).

    ``device:N`` is camera N (``/dev/videoN``), ``scheme://...`` a stream (RTSP, HTTP),
    anything else a video file, which must exist.
    """
    if spec.startswith("device:"):
        index = spec.removeprefix("device:")
        if not index.isdigit():
            raise ConfigError(None, "hotspot.frames", "device:N with N a camera index (device:0)", spec)
        return int(index), True
    if "://" in spec:
        return spec, True
    if not Path(spec).is_file():
        raise ConfigError(None, "hotspot.frames", "an existing video file, a folder, device:N or a URL", spec)
    return spec, False


class VideoCaptureFrameSource(FrameSource):
    """Frames from OpenCV ``VideoCapture``: a camera (``device:N``), a stream URL (RTSP,
    HTTP) or a video file.

    A live source (camera, stream) is read by a thread of its own that keeps only the
    newest frame, stamped with the clock's wall time when it arrived (a capture buffers:
    reading on demand would hand out stale frames, and a stalled stream must not stall the
    loop).  A source that fails to open or stops delivering is released and reopened with
    exponential backoff (``min_backoff_s`` doubling up to ``max_backoff_s``), with one
    warning per outage and one line when frames come back.

    A video file stands in for a camera: it plays at its own frame rate on the clock from
    when it was opened, frame ``k`` exposed at ``t_open + k / fps`` (wall time); after its
    end its last frame stays the newest, and ages out after ``max_age_s``.

    ``grab(t)`` returns the newest frame not older than ``max_age_s`` (for a file, at least
    1.5 frame intervals), as 8-bit grey.
    """

    #: OpenCV's open and read timeouts for network streams, ms.
    STREAM_TIMEOUT_MS = 5000

    def __init__(
        self,
        spec: str,
        clock: Clock | None = None,
        *,
        live: bool | None = None,
        max_age_s: float = 10.0,
        min_backoff_s: float = 1.0,
        max_backoff_s: float = 60.0,
    ):
        target, is_live = capture_target(spec)
        self.spec, self.target = spec, target
        self.live = is_live if live is None else live
        self.clock: Clock = clock if clock is not None else RealClock()
        self.max_age_s = max_age_s
        self.min_backoff_s, self.max_backoff_s = min_backoff_s, max_backoff_s
        self.opens = 0  # successful opens (1 + reopens after a drop)
        self.frames_read = 0
        self._latest: CameraFrame | None = None
        self._lock = threading.Lock()
        self._new_frame = threading.Event()
        self._stop = threading.Event()
        self._cap: Any = None
        self._thread: threading.Thread | None = None
        if self.live:
            self._thread = threading.Thread(target=self._read_live, name=f"camera {spec}", daemon=True)
            self._thread.start()
        else:
            self._open_file()

    def _open(self) -> Any:
        if isinstance(self.target, str) and "://" in self.target:
            ms = self.STREAM_TIMEOUT_MS
            params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, ms]
            return cv2.VideoCapture(self.target, cv2.CAP_ANY, params)
        return cv2.VideoCapture(self.target)

    # -- a video file, played on the clock ------------------------------------------------
    def _open_file(self) -> None:
        cap = self._open()
        if not cap.isOpened():
            raise ConfigError(None, "hotspot.frames", "a video file OpenCV can read", self.spec)
        self._cap = cap
        fps = cap.get(cv2.CAP_PROP_FPS)
        self.fps = fps if math.isfinite(fps) and fps > 0 else 1.0
        # a frame is the newest until the next one: a slow file must not read as "no frame"
        self.max_age_s = max(self.max_age_s, 1.5 / self.fps)
        count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.frame_count = int(count) if math.isfinite(count) and count > 0 else None
        self.t_open, self.mono_open = self.clock.now(), self.clock.monotonic()
        self._index = -1  # the frame the capture returned last
        self._ended = False
        self.opens = 1

    def _file_frame(self) -> CameraFrame | None:
        k = int((self.clock.monotonic() - self.mono_open) * self.fps + 1e-9)
        if self.frame_count is not None:
            k = min(k, self.frame_count - 1)  # after the end: its last frame, until too old
        if self._ended or self._cap is None:
            return self._latest
        if k == self._index:
            return self._latest
        if k > self._index + 1:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, k)
        ok, image = self._cap.read()
        grey = grey8(image) if ok and image is not None else None
        if grey is None:
            self._ended = True
            log.info("video %s ended after %d frame(s)", self.spec, self.frames_read)
            return self._latest
        self._index = k
        self.frames_read += 1
        self._latest = CameraFrame(grey, self.t_open + k / self.fps, f"{Path(self.spec).name}#{k}")
        return self._latest

    # -- a live camera or stream, read by a thread -------------------------------------------
    def _read_live(self) -> None:
        backoff = self.min_backoff_s
        outage = False
        while not self._stop.is_set():
            cap = self._open()
            if cap.isOpened():
                self._cap = cap
                self.opens += 1
                n = self._read_until_dropped(cap)
                cap.release()
                self._cap = None
                if n:
                    backoff = self.min_backoff_s
                    outage = False
            else:
                cap.release()
            if self._stop.is_set():
                break
            if not outage:
                log.warning("camera %s: no frames (cannot open, or the stream dropped): reopening", self.spec)
                outage = True
            self._stop.wait(backoff)
            backoff = min(2 * backoff, self.max_backoff_s)

    def _read_until_dropped(self, cap: Any) -> int:
        n = 0
        while not self._stop.is_set():
            ok, image = cap.read()
            grey = grey8(image) if ok and image is not None else None
            if grey is None:
                break
            if n == 0 and self.opens > 1:
                log.info("camera %s: frames again", self.spec)
            n += 1
            self.frames_read += 1
            t = self.clock.now()
            with self._lock:
                self._latest = CameraFrame(grey, t, f"{self.spec}@{t:.3f}")
            self._new_frame.set()
        return n

    # -- the interface ------------------------------------------------------------------------
    def grab(self, t: float) -> CameraFrame | None:
        if self.live:
            with self._lock:
                frame = self._latest
        else:
            frame = self._file_frame()
        if frame is None or t - frame.time > self.max_age_s:
            return None
        return frame

    def first_frame(self, t: float, timeout_s: float = 5.0) -> CameraFrame | None:
        if self.live:
            self._new_frame.wait(timeout_s)
            with self._lock:
                return self._latest
        return self._file_frame()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=self.STREAM_TIMEOUT_MS / 1000 + 1)
        elif self._cap is not None:
            self._cap.release()
            self._cap = None


class CameraSunSensor:
    """Frames -> :class:`SunObservation` with an estimator exposing
    ``estimate_image(image, t)`` whose result has ``observation()``.

    A frame is judged first (:func:`judge_frame`): a black or saturated frame never
    reaches the estimator, nor does the frame it had last time (``same frame``: a camera
    slower than the loop's looks must not count one measurement twice).  ``outcomes``
    counts what each look gave: ``found``, ``no frame`` (the source had none, or none
    recent), ``same frame``, or the reason the frame was refused; a camera whose glares are
    refused off the sun by one angle, frame after frame, is said once to have moved
    (:class:`.mount_watch.MountWatch`).

    ``interval_s``: :meth:`observations` looks once per interval (0: at every call).
    ``colour``: hand the estimator the frame in colour (BGR; the fisheye's pipelines) rather
    than grey.  ``prior(t)``: the expected sun at ``t`` (an object with ``az_deg``,
    ``el_deg``, ``sigma_deg``, e.g. the sun-path filter's prediction, or None), passed to
    the estimator as its ``prior``.
    """

    def __init__(
        self,
        frames: FrameSource,
        estimator,
        name: str = "hotspot",
        *,
        interval_s: float = 0.0,
        colour: bool = False,
        prior: Callable[[float], Any] | None = None,
    ):
        self.frames = frames
        self.estimator = estimator
        self.name = name
        self.interval_s = float(interval_s)
        self.colour = colour
        self.prior = prior
        self.outcomes: Counter[str] = Counter()
        self.last_outcome = ""
        self.mount = MountWatch()  # its glares refused off the sun by one angle: said once
        self._last_frame: tuple[float, str] | None = None
        self._last_look = -math.inf

    def observations(self, t: float) -> list[SunObservation]:
        """The observation of the look at ``t`` when one is due (``interval_s`` since the
        last look), as a list: empty when not due or nothing was found."""
        if t - self._last_look < self.interval_s - 1e-6:
            return []
        self._last_look = t
        obs = self.observe(t)
        return [obs] if obs is not None else []

    def observe(self, t: float) -> SunObservation | None:
        frame = self.frames.grab(t)
        if frame is None:
            self._outcome("no frame")
            return None
        if (frame.time, frame.name) == self._last_frame:
            # a camera slower than the loop: one measurement is fed to the filter once
            self._outcome("same frame")
            return None
        self._last_frame = (frame.time, frame.name)
        image: np.ndarray | None = frame.image
        if frame.image.ndim != 2 or frame.image.dtype != np.uint8:
            image = grey8(frame.image)
        bad = "unsupported_image_format" if image is None else judge_frame(image)
        if bad:
            self._outcome(bad)
            return None
        if self.colour and frame.image.ndim == 3 and frame.image.dtype == np.uint8:
            image = frame.image
        try:
            if self.prior is not None:
                result = self.estimator.estimate_image(image, frame.time, prior=self.prior(frame.time))
            else:
                result = self.estimator.estimate_image(image, frame.time)
            obs = result.observation()
        except Exception as exc:  # a fault of the measurement costs its look, never the loop
            kind = type(exc).__name__
            if not any(k.startswith(f"estimator_error: {kind}") for k in self.outcomes):
                log.exception(
                    "%s camera: the estimator failed on frame %r (logged once)", self.name, frame.name
                )
            self._outcome(f"estimator_error: {kind}")
            return None
        self._outcome("found" if obs is not None else getattr(result, "reason", "") or "not found")
        said = self.mount.observe(frame.time, result)
        if said:
            (log.warning if self.mount.moved else log.info)("%s camera: %s", self.name, said)
        return obs

    def _outcome(self, what: str) -> None:
        self.outcomes[what] += 1
        self.last_outcome = what

    def close(self) -> None:
        self.frames.close()
