"""Records of the control loop: what happened to one tracker in one cycle, and the loop's
bookkeeping per tracker."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from .config import TrackerConfig
from .drives.base import DriveLink, DriveState
from .health import DriveHealth


@dataclass
class CycleRecord:
    """What happened to one tracker in one cycle (degrees; time in POSIX seconds).

    ``health`` is the drive's health after the cycle (``ok``, ``degraded``, ``lost``) and
    ``health_reason`` why; ``error`` is this cycle's failure, if any; ``alarms`` the
    plant's weather alarms in force.
    """

    time: float
    tracker: str
    mode: str
    reason: str
    source: str
    sun_az_deg: float
    sun_el_deg: float
    targets_deg: tuple[float, ...] = ()
    actual_deg: tuple[float, ...] = ()
    status: int = 0
    axis_modes: tuple[str, ...] = ()
    backtracking: bool = False
    error: str = ""
    latency_s: float = 0.0  # wall time from the cycle's start until this row was done
    health: str = "ok"
    health_reason: str = ""
    alarms: tuple[str, ...] = ()


@dataclass
class TrackerRuntime:
    """The loop's state of one tracker and its drive."""

    cfg: TrackerConfig
    drive: DriveLink
    last_targets: tuple[float, ...] = ()
    last_state: DriveState | None = None
    last_heartbeat: float = -math.inf
    configured: bool = False
    uptime_s: float | None = None  # the drive's last reported uptime, s
    uptime_at: float = 0.0  # when it was read (the clock's monotonic time)
    restarts_seen: int = 0  # the drive's ``restarts`` when it was last configured
    index: int = 0
    errors: int = 0
    health: DriveHealth = field(default_factory=DriveHealth)
