"""Replay recorded camera frames through the whole controller (``heliotrack replay``).

A frame folder (file names carry their UTC time, ``2026-03-20T10-15-00Z.png``) or a video
file (a start time and a frame rate) feeds the configured camera sensor; everything else
runs as in ``simulate``: the sun-path filter, the modes, the setpoints and the emulated
drives, on a simulated clock.  The run is scored against the recording's ``truth.csv``
when there is one (:mod:`heliotrack.recorded_truth`), else
against the ephemeris (pvlib SPA), with the scenario's clear sky for energy.

``truth.csv`` columns: ``time_utc`` (ISO 8601 with a zone), ``sun_az_deg``,
``sun_el_deg``, ``sun_visible`` (0/1), and optionally ``ghi_w_m2``, ``dni_w_m2``,
``dhi_w_m2``, ``beam_transmittance`` (the sky the pyranometer and the energy tally see).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from controller.config import Config
from controller.errors import ConfigError, InputError
from controller.sun.camera import IMAGE_SUFFIXES, CameraFrame, FolderFrameSource, FrameSource
from controller.timestamps import names_without_zone, time_from_name, to_iso, zone_warning

from .output import check_out_dir, write_summary
from .recorded_truth import MAX_AGE_S, TOLERANCE_S, TRUTH_FILE, TRUTH_GAP_DEG, EphemerisTruth, RecordedTruth
from .renderers import camera_sensor
from .scenario import as_scenario
from .simulate import ScenarioRun, Span

VIDEO_SUFFIXES = {".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm", ".mjpeg", ".mjpg"}
#: The longest replay (days): a year of frames; beyond, a wrong --start or --fps.
MAX_SPAN_DAYS = 366


def _grey(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    return image


# -- frames ------------------------------------------------------------------------------


class RecordedFrames(FrameSource):
    """Frames of a folder or a video, with the times they were exposed at.

    Each frame is handed out once: a later cycle that finds no newer frame gets none (the
    sun-path filter predicts), instead of observing the same exposure again as if it
    were new.
    """

    times: np.ndarray

    def __init__(self, source: Path):
        self.source = source
        self.last_time = -math.inf
        self.names: list[str] = []  # the frames' file names, when they are files

    def fresh(self, frame: CameraFrame | None) -> CameraFrame | None:
        if frame is None or frame.time <= self.last_time:
            return None
        self.last_time = frame.time
        return frame

    @property
    def cadence_s(self) -> float:
        return float(np.median(np.diff(self.times))) if self.times.size > 1 else MAX_AGE_S


class FolderFrames(RecordedFrames):
    """A folder of timestamped images (:class:`~controller.sun.camera.FolderFrameSource`),
    tolerant of names rounded to the millisecond; colour frames are turned grey."""

    def __init__(self, folder: Path, max_age_s: float = MAX_AGE_S):
        super().__init__(folder)
        self.unreadable: list[str] = []  # frames that could not be read when their turn came
        try:
            self.inner = FolderFrameSource(folder, max_age_s=max_age_s)
        except ConfigError as exc:
            raise InputError(f"{folder}: expected {exc.expected}, got {exc.got}") from None
        self.times = self.inner.times
        self.names = [p.name for _, p in self.inner.frames]
        if self.times.size == 0:
            suffixes = ", ".join(sorted(IMAGE_SUFFIXES))
            raise InputError(
                f"{folder}: no images ({suffixes}) named by their time, e.g. 2026-03-20T10-15-00Z.png"
            )

    def grab(self, t: float) -> CameraFrame | None:
        i = int(np.searchsorted(self.times, t + TOLERANCE_S, side="right")) - 1
        if i < 0 or self.times[i] <= self.last_time:
            return None  # no frame yet, or the newest one was already used: skip reading it
        got = self.inner.grab(t + TOLERANCE_S)
        if got is None and t + TOLERANCE_S - self.times[i] <= self.inner.max_age_s:
            self.unreadable.append(self.inner.frames[i][1].name)  # truncated, empty, not an image
            self.last_time = float(self.times[i])  # told once, not at every cycle until the next
        frame = self.fresh(got)
        return None if frame is None else replace(frame, image=_grey(frame.image))


class VideoFrames(RecordedFrames):
    """A video file: frame ``k`` was exposed at ``start + k / fps``."""

    def __init__(self, path: Path, start: float, fps: float | None, max_age_s: float = MAX_AGE_S):
        super().__init__(path)
        self.cap = cv2.VideoCapture(str(path))
        if not self.cap.isOpened():
            raise InputError(f"{path}: not a video OpenCV can read")
        fps = fps or float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if not fps or not math.isfinite(fps) or fps <= 0:
            raise InputError(f"{path}: the video gives no frame rate: pass --fps")
        n = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        if n <= 0:
            raise InputError(f"{path}: no frames")
        self.fps, self.start, self.max_age_s = fps, start, max_age_s
        self.times = start + np.arange(n) / fps
        self.pos = 0  # index of the next frame the capture will decode

    def grab(self, t: float) -> CameraFrame | None:
        k = int(math.floor((t - self.start) * self.fps + 1e-6))
        if (
            k < 0
            or k >= self.times.size
            or t - self.times[k] > self.max_age_s
            or self.times[k] <= self.last_time
        ):
            return None
        if k < self.pos or k - self.pos > 50:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, k)
            self.pos = k
        while self.pos < k:
            self.cap.grab()
            self.pos += 1
        ok, image = self.cap.read()
        self.pos += 1
        if not ok or image is None:
            return None
        return self.fresh(CameraFrame(_grey(image), float(self.times[k]), f"{self.source.name}#{k}"))


def open_frames(source: Path, start: float | None = None, fps: float | None = None) -> RecordedFrames:
    """The frames of a folder or a video file (``start``: the video's first frame, POSIX s;
    by default the time in its file name)."""
    source = Path(source)
    if source.is_dir():
        if fps is not None:
            raise InputError("--fps: only for a video (a folder's frames are named by their time)")
        return FolderFrames(source)
    if not source.is_file():
        raise InputError(f"{source}: no such folder or video file")
    if source.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(
            f"{source}: expected a folder of frames or a video ({', '.join(sorted(VIDEO_SUFFIXES))})"
        )
    if start is None:
        start = time_from_name(source.name)
    if start is None:
        raise InputError(f"{source}: the video's name carries no time: pass --start (its first frame, UTC)")
    return VideoFrames(source, start, fps)


# -- the run -----------------------------------------------------------------------------


@dataclass(frozen=True)
class ReplayPlan:
    span: Span
    warnings: list[str]


def _span_text(a: float, b: float) -> str:
    fmt = "%Y-%m-%d %H:%M:%S"
    return f"{datetime.fromtimestamp(a, UTC).strftime(fmt)} to {datetime.fromtimestamp(b, UTC).strftime(fmt)} UTC"


def plan(frames: RecordedFrames, period_s: float, start: float | None, hours: float | None) -> ReplayPlan:
    """The run's span (from the frames unless ``start``/``hours`` say otherwise) and what
    the frames leave uncovered: there the controller has no camera and falls back on the
    sun-path filter's prediction or the ephemeris, which the user must be told."""
    first, last = float(frames.times[0]), float(frames.times[-1])
    t0 = first if start is None else start
    if hours is not None:
        n = max(1, round(hours * 3600.0 / period_s))
    elif last < t0:
        raise InputError(
            f"--start: after the last frame ({to_iso(last)}); the frames cover {_span_text(first, last)}"
        )
    else:  # to the last frame: the first cycle at or after it (a frame off the grid had been left out)
        n = 1 + max(0, math.ceil((last - t0 - TOLERANCE_S) / period_s))
    if n * period_s > MAX_SPAN_DAYS * 86400.0:  # a wrong --start or --fps: days of wall time
        raise InputError(
            f"the run would span {_span_text(t0, t0 + n * period_s)}, over {MAX_SPAN_DAYS} days "
            f"(the frames cover {_span_text(first, last)}): check --start, --hours and --fps"
        )
    warnings = []
    reach = max(MAX_AGE_S, 1.5 * frames.cadence_s, period_s)
    if t0 < first - reach or t0 + n * period_s > last + reach:
        warnings.append(
            f"the frames cover {_span_text(first, last)}, the run {_span_text(t0, t0 + n * period_s)}: "
            "outside the frames the controller has no camera and tracks on prediction or the ephemeris"
        )
    gaps = np.flatnonzero(np.diff(frames.times) > max(reach, 3 * frames.cadence_s))
    if gaps.size:
        a, b = frames.times[gaps[0]], frames.times[gaps[0] + 1]
        warnings.append(
            f"{gaps.size} gap(s) in the frames (the first {_span_text(float(a), float(b))}): "
            "no camera there, the controller falls back on prediction or the ephemeris"
        )
    used = min(n, frames.times.size)
    if frames.times.size > 1.5 * n:  # a cycle takes one frame: the rest are never looked at
        warnings.append(
            f"{frames.times.size} frames, one every {frames.cadence_s:g} s, for {n} cycles of "
            f"{period_s:g} s: at most {used} of them are used (a video's --fps, or the "
            "configuration's control.period_s?)"
        )
    naive = zone_warning(names_without_zone(getattr(frames, "names", [])), frames.times.size)
    if naive:
        warnings.append(naive)
    label = to_iso(t0)
    return ReplayPlan(Span(t0, n, label), warnings)


def replay_config(config: Config) -> Config:
    """The configuration with its camera fed by the replay (``frames = "hil"``)."""
    sensor = camera_sensor(config)
    if sensor is None:
        raise ConfigError(
            config.file,
            "control.sun_source",
            'a camera sensor to replay frames into (e.g. "hotspot")',
            config.control.sun_source,
        )
    table = getattr(config, sensor)
    return replace(config, **{sensor: replace(table, frames="hil")})


def run_replay(
    config: Config,
    source: Path,
    *,
    start: float | None = None,
    fps: float | None = None,
    hours: float | None = None,
    speed: float | None = None,
    truth_file: Path | None = None,
    out_dir: Path | None = None,
    report: bool = False,
    progress: bool = False,
    warn=None,
) -> dict:
    """Replay ``source`` through the controller; return (and write) the summary.

    ``warn(text)`` is told what the frames and the truth do not cover, and what the run
    could not use of them; both go into the summary's ``warnings``.  ``out_dir`` is made
    only once the frames are open (``report``: check that its ``report/`` can be written).
    """
    scenario = as_scenario(replay_config(config))
    frames = open_frames(Path(source), start if not Path(source).is_dir() else None, fps)
    p = plan(frames, scenario.control.period_s, start if Path(source).is_dir() else None, hours)
    hil = scenario.hil
    fallback = EphemerisTruth(scenario.site, hil.linke_turbidity)
    if truth_file is None:
        near = (Path(source) if Path(source).is_dir() else Path(source).parent) / TRUTH_FILE
        truth_file = near if near.is_file() else None
    warnings = list(p.warnings)
    recorded = RecordedTruth(truth_file, fallback) if truth_file is not None else None
    if recorded is not None:
        times = p.span.t0 + np.arange(p.span.n_cycles) * scenario.control.period_s
        uncovered = ~recorded.covered(times)
        if uncovered.any():
            warnings.append(
                f"{truth_file} does not cover {int(uncovered.sum())} of {times.size} cycles: "
                "scored against the ephemeris there"
            )
        if recorded.worst_gap_deg > TRUTH_GAP_DEG:
            warnings.append(
                f"{truth_file}: its sun is up to {recorded.worst_gap_deg:.1f} deg from the ephemeris's at the "
                f"site ({scenario.site.latitude:g}, {scenario.site.longitude:g}): another site, another "
                "azimuth convention (from south?) or times in another zone; the score is against it"
            )
    for w in warnings:
        if warn is not None:
            warn(w)
    if out_dir is not None:
        out_dir = check_out_dir(Path(out_dir), folders=("report",) if report else ())
    extra = {
        "replay": {
            "source": str(Path(source).resolve()),
            "frames": int(frames.times.size),
            "first_frame_utc": to_iso(float(frames.times[0])),
            "last_frame_utc": to_iso(float(frames.times[-1])),
            "truth": str(Path(truth_file).resolve()) if truth_file is not None else "ephemeris",
            "speed": speed,
        },
        **({"warnings": warnings} if warnings else {}),
    }
    run = ScenarioRun(
        scenario,
        p.span,
        progress=progress,
        frames=frames,
        truth=recorded if recorded is not None else fallback,
        command="replay",
        speed=speed,
        extra=extra,
    )
    summary = run.execute(out_dir)
    after = _frame_warnings(frames, summary)
    for w in after:
        if warn is not None:
            warn(w)
    if after:
        summary["warnings"] = [*summary.get("warnings", []), *after]
        if out_dir is not None and summary["cycles"]:  # the report, built from it, says them too
            write_summary(Path(out_dir), summary)
    return summary


def _frame_warnings(frames: RecordedFrames, summary: dict) -> list[str]:
    """What the run could not use of the frames: said after it, since reading every frame
    up front would cost as much as the run."""
    out = []
    bad = getattr(frames, "unreadable", [])
    if bad:
        shown = ", ".join(bad[:3]) + (f" and {len(bad) - 3} more" if len(bad) > 3 else "")
        out.append(f"{len(bad)} frame(s) could not be read (empty, truncated or not an image): {shown}")
    outcomes = summary.get("camera_frames") or {}
    if outcomes.get("size_mismatch"):
        out.append(
            f"{outcomes['size_mismatch']} frame(s) are not the size of the camera's calibration "
            "bundle (size_mismatch): another camera's frames, or resized"
        )
    if summary.get("cycles") and not outcomes.get("found"):
        out.append("no frame gave a sun: the run tracked on prediction and the ephemeris alone")
    return out
