"""Clocks: everything that reads the time or waits takes one, so a day can run in seconds.

Times are float POSIX seconds (UTC).  :class:`SimClock` only moves when told to, so the
controller and an in-process emulator that share it see the same instant.
"""

from __future__ import annotations

import threading
import time
from datetime import UTC, datetime
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Current time, POSIX seconds (UTC): for records and the sun.  May step (NTP)."""

    def monotonic(self) -> float:
        """Seconds on a clock that never steps: for intervals, schedules and timeouts."""

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of this clock's time."""


class RealClock:
    """The wall clock, and the system's monotonic clock for intervals."""

    def now(self) -> float:
        return time.time()

    def monotonic(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class SimClock:
    """A simulated clock; :meth:`sleep` advances it instantly.

    :meth:`monotonic` is the true time of the simulation (what the world runs on);
    :meth:`now` is the controller's wall clock, which :meth:`step_wall` can set off by an
    offset to emulate an NTP step.  Thread-safe: an emulator serving Modbus in another
    thread may read it while the control loop advances it.
    """

    def __init__(self, start: float | datetime):
        if isinstance(start, datetime):
            if start.tzinfo is None:
                raise ValueError("SimClock start must be timezone-aware")
            start = start.timestamp()
        self._t = float(start)
        self._wall_offset = 0.0
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t + self._wall_offset

    def monotonic(self) -> float:
        with self._lock:
            return self._t

    def step_wall(self, seconds: float) -> None:
        """Fault injection: the wall clock jumps by ``seconds`` (either way); true time and
        :meth:`monotonic` do not."""
        with self._lock:
            self._wall_offset += seconds

    def sleep(self, seconds: float) -> None:
        if seconds < 0:
            raise ValueError("cannot sleep a negative time")
        with self._lock:
            self._t += seconds

    def advance_to(self, t: float) -> None:
        with self._lock:
            if t < self._t:
                raise ValueError("a clock cannot go backwards")
            self._t = t


def to_datetime(t: float) -> datetime:
    """POSIX seconds -> timezone-aware UTC datetime."""
    return datetime.fromtimestamp(t, tz=UTC)
