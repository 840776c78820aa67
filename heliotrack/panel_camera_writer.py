"""A capture daemon for an emulated camera: timestamped frames into a folder, in real time.

``heliotrack hil drive --panel-camera DIR`` runs one beside the drive it emulates: a
thread that samples the panel's pose and the wall clock together, renders the frame,
and writes it as ``DIR/2026-03-20T10-15-00Z.png`` the way a real camera's capture daemon
(or an FTP upload) fills the folder that the controller's ``FolderFrameSource`` reads.

* Frames are taken on whole seconds of the wall clock, so that a name's 1-s resolution
  is the frame's time (to the thread's wake-up latency, a few ms); an interval that is not
  a whole number of seconds is kept on average (1.5 s: 2, 1, 2, 1 ... s).
* Each frame is written under a name with no image suffix and then renamed: a reader
  never sees half a PNG.
* Only the ``keep`` newest frames stay; older files with a canonical frame name go (other
  files in the folder are left alone), so a long run does not fill the disk.
* A failure (disk full, folder gone, a render that raises) is said once on stderr until a
  frame is written again; the thread goes on, the drive beside it is never held up.
"""

from __future__ import annotations

import math
import os
import re
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from hil.skycam.dataset import frame_name

#: What this writer names its frames (``hil.skycam.dataset.frame_name``); only these are pruned.
FRAME_RE = re.compile(r"^\d{4}-\d{2}-\d{2}T\d{2}-\d{2}-\d{2}Z\.png$")
PART_SUFFIX = ".part"  # no image suffix: FolderFrameSource does not list it

Render = Callable[[float, list[float]], np.ndarray]


def next_due(now: float, interval: float) -> float:
    """The next capture instant at or after ``now`` (POSIX s): the next slot of the
    ``interval`` grid (s), moved on to the whole second its name will carry."""
    slot = math.ceil(now / interval) * interval
    return float(math.ceil(slot))


def write_atomically(folder: Path, name: str, image: np.ndarray) -> Path:
    """Encode ``image`` (BGR uint8) as PNG into ``folder/name`` through a temporary name.

    Raises
    ------
    OSError
        The folder is gone or full, or the image cannot be encoded.
    """
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"cannot encode {name} as PNG")
    part = folder / f".{name}{PART_SUFFIX}"
    try:
        with open(part, "wb") as f:
            f.write(data.tobytes())
        os.replace(part, folder / name)
    except OSError:
        part.unlink(missing_ok=True)
        raise
    return folder / name


def prune(folder: Path, keep: int) -> int:
    """Delete all but the ``keep`` newest canonical frames in ``folder``; returns how many went.

    Canonical names sort by time, so the name order is the time order.
    """
    frames = sorted(p.name for p in folder.iterdir() if FRAME_RE.match(p.name))
    old = frames[: max(len(frames) - keep, 0)]
    for name in old:
        (folder / name).unlink(missing_ok=True)  # a reader or a user may have taken it
    return len(old)


def remove_leftover_parts(folder: Path) -> None:
    """Delete temporary frames a killed writer left behind (none is in flight at start)."""
    for p in folder.iterdir():
        frame = p.name.removeprefix(".").removesuffix(PART_SUFFIX)
        if p.name == f".{frame}{PART_SUFFIX}" and FRAME_RE.match(frame):
            p.unlink(missing_ok=True)


class PanelCameraWriter:
    """A thread that writes what ``render`` sees into ``folder`` every ``interval`` s.

    Parameters
    ----------
    folder : Path
        An existing folder the frames go into.
    render : callable
        ``render(t, angles)`` -> BGR uint8 image: the camera at POSIX ``t`` (s) on a panel
        at ``angles`` (deg).
    angles : callable
        The panel's true angles now (deg), e.g. ``DriveFirmware.panel_angles``.
    interval : float
        Seconds between frames, >= 1 (names have 1-s resolution).
    keep : int
        How many of the newest frames stay in ``folder``, >= 1.
    clock : callable
        Wall clock, POSIX s (the frames' names are UTC).
    """

    def __init__(
        self,
        folder: Path,
        render: Render,
        angles: Callable[[], list[float]],
        *,
        interval: float,
        keep: int,
        clock: Callable[[], float] = time.time,
    ):
        if not interval >= 1.0 or keep < 1:
            raise ValueError(f"interval {interval} s must be >= 1, keep {keep} >= 1")
        self.folder = folder
        self.render = render
        self.angles = angles
        self.interval = interval
        self.keep = keep
        self.clock = clock
        self.written = 0
        self.failing = False  # a failure was said and no frame was written since
        self._last_name = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="panel-camera", daemon=True)

    def start(self) -> PanelCameraWriter:
        remove_leftover_parts(self.folder)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Let the frame in hand finish and end the thread (a daemon: never holds up exit)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def capture(self) -> Path | None:
        """Take one frame now: pose and time sampled together, then render, write, prune.

        Returns the file written, or None when this second already has its frame (the wall
        clock stepped back).
        """
        t = self.clock()
        angles = self.angles()  # the pose at t: a moving panel is drawn where it was then
        name = frame_name(t)
        if name == self._last_name:
            return None
        path = write_atomically(self.folder, name, self.render(t, angles))
        self._last_name = name
        prune(self.folder, self.keep)
        return path

    def _run(self) -> None:
        while self._wait_until(next_due(self.clock(), self.interval)):
            try:
                if self.capture() is not None:
                    self.written += 1
                    self._recovered()
            except Exception as exc:  # noqa: BLE001 - whatever breaks, the drive serves on
                self._failed(exc)

    def _wait_until(self, due: float) -> bool:
        """Sleep until the wall clock reads ``due``; False when asked to stop."""
        while (left := due - self.clock()) > 0:
            if left > self.interval + 1.0:  # the wall clock stepped back: a new grid
                due = next_due(self.clock(), self.interval)
                continue
            if self._stop.wait(left):
                return False
        return not self._stop.is_set()

    def _failed(self, exc: Exception) -> None:
        if not self.failing:
            self.failing = True
            print(
                f"panel camera: warning: no frame written to {self.folder}: {type(exc).__name__}: {exc} "
                "(said once; the drive serves on)",
                file=sys.stderr,
                flush=True,
            )

    def _recovered(self) -> None:
        if self.failing:
            self.failing = False
            print(f"panel camera: frames written to {self.folder} again", file=sys.stderr, flush=True)
