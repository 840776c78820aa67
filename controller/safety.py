"""Which weather stow is in force, and the angles it puts each tracker at.

One place decides, in the order of priority: wind (including a lost anemometer), then
hail, then snow; requests come from the anemometer (:class:`~controller.weather.WindMonitor`),
an operator or SCADA (:meth:`SafetyState.request`), and the flag file of ``[stow]``.
The loop asks :meth:`SafetyState.order` once per cycle; the wind part is also updated
between cycles (:meth:`update_wind`) so that a gust stows the plant within seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .config import DualAxisTracker, SingleAxisTracker, TrackerConfig
from .weather import StowConfig, WindConfig, WindMonitor, WindSample, WindState, read_flag_file

#: Weather stow kinds, highest priority first.
PRIORITY = ("wind", "hail", "snow")


@dataclass(frozen=True)
class StowOrder:
    """A weather stow in force: its kind ("wind", "hail", "snow") and why."""

    kind: str
    reason: str


class SafetyState:
    """Weather stow requests and their arbitration.

    Parameters
    ----------
    wind, stow : the ``[wind]`` and ``[stow]`` tables (either may be None)
    start : POSIX s; the anemometer's silence is counted from here
    warn : callable taking one line, for a flag file that cannot be read or obeyed
    """

    def __init__(self, wind: WindConfig | None, stow: StowConfig | None, start: float, warn=None):
        self.wind_config = wind
        self.stow_config = stow or StowConfig()
        self.monitor = WindMonitor(wind, start) if wind is not None else None
        self.wind = WindState(False, False)
        self.requests: dict[str, str] = {}  # source -> "snow" / "hail"
        self._warn = warn or (lambda line: None)
        self._last_flag_problem = ""

    # -- inputs ---------------------------------------------------------------------
    def update_wind(self, t: float, sample: WindSample | None) -> WindState:
        """Feed one anemometer poll (None: failed or implausible); returns the new state."""
        if self.monitor is not None:
            self.wind = self.monitor.update(t, sample)
        return self.wind

    def request(self, source: str, kind: str | None) -> None:
        """Snow or hail stow asked for by ``source`` ("operator", "sunspec", "flag file");
        ``None`` withdraws that source's request."""
        if kind is None:
            self.requests.pop(source, None)
        elif kind in ("snow", "hail"):
            self.requests[source] = kind
        else:
            raise ValueError(f"unknown stow request {kind!r}")

    def read_flag(self) -> None:
        """Take the ``[stow] flag_file`` into account (read every cycle)."""
        path = self.stow_config.flag_file
        if path is None:
            return
        got = read_flag_file(path)
        if got in (None, "snow", "hail"):
            self.request("flag file", got)
            self._last_flag_problem = ""
        elif got != self._last_flag_problem:  # say it once, not every cycle
            self._warn(str(got))
            self._last_flag_problem = str(got)

    # -- decision --------------------------------------------------------------------
    def order(self) -> StowOrder | None:
        """The weather stow in force, if any (wind first, then hail, then snow)."""
        if self.wind.stow:
            return StowOrder("wind", self.wind.reason or "wind")
        for kind in ("hail", "snow"):
            sources = sorted(s for s, k in self.requests.items() if k == kind)
            if sources:
                return StowOrder(kind, f"{kind} stow ({', '.join(sources)})")
        return None

    @property
    def alarms(self) -> list[str]:
        """Weather alarms for logs and SCADA (a lost anemometer alarms even when it does
        not stow)."""
        out = []
        if self.wind.alarm:
            out.append(self.wind.reason)
        out += [f"{k} stow requested by {s}" for s, k in sorted(self.requests.items())]
        return out

    def angles(self, tracker: TrackerConfig, kind: str) -> tuple[float, ...]:
        """Stow angles (deg) of ``tracker`` for a weather stow of ``kind``, inside its limits."""
        w, s = self.wind_config, self.stow_config
        if isinstance(tracker, SingleAxisTracker):
            rot = {
                "wind": w.single_axis_deg if w else tracker.stow,
                "snow": s.snow_single_axis_deg,
                "hail": s.hail_single_axis_deg,
            }[kind]
            return (min(max(rot, -tracker.max_angle), tracker.max_angle),)
        assert isinstance(tracker, DualAxisTracker)
        el = {
            "wind": w.dual_axis_elevation_deg if w else tracker.stow[1],
            "snow": s.snow_dual_axis_elevation_deg,
            "hail": s.hail_dual_axis_elevation_deg,
        }[kind]
        lo, hi = tracker.elevation_limits
        return tracker.stow[0], min(max(el, lo), hi)


def drive_stow_angles(safety: SafetyState, tracker: TrackerConfig) -> tuple[float, ...]:
    """What a drive's STOW_ANGLE holds: the wind stow when wind is watched (the safest
    place to be unattended, and where the drive's watchdog sends it), else the night stow."""
    if safety.wind_config is not None:
        return safety.angles(tracker, "wind")
    return tracker.stow_angles


def clamp_targets(tracker: TrackerConfig, targets: list[float]) -> list[float]:
    """The last guard before the wire: every axis target inside its soft limits, and a
    target that is not a finite number replaced by the axis's stow angle."""
    out = []
    for angle, stow, (lo, hi) in zip(targets, tracker.stow_angles, tracker.soft_limits):
        a = float(angle) if isinstance(angle, (int, float)) and math.isfinite(angle) else stow
        out.append(min(max(a, lo), hi))
    return out
