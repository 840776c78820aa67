"""Per-drive health: ok, degraded or lost, with the reason; what to do about faults.

The loop reports every exchange to a :class:`DriveHealth`, which decides:

* link: a failed cycle makes the drive ``degraded``; ``lost_after`` failures in a row make
  it ``lost``, and the loop then closes the link and reconnects with exponential backoff
  (one period, doubling, at most ``max_backoff_s``), probing it once a cycle in between
  (``DriveLink.probe``) so that a drive that answers again is back at once;
* faults: a latched fault (stall, limit switch, encoder...) is named, and CLEAR_FAULT is sent
  ``max_fault_clears`` times, ``clear_interval_s`` apart; a fault that survives them leaves
  the drive ``lost`` ("needs service"), and CLEAR_FAULT is still tried every
  ``service_retry_s``, so that a drive whose cause went away (ice melted, a switch
  released) is back within that time by itself.  The count restarts only once the drive
  has shown no fault for ``fault_free_s`` (two readings at least): a fault that comes back
  as soon as the drive moves (an over-current under a load that lasts) is one fault that
  persists, not a new one each time, and ends in "needs service" too.  A
  stall's cause cannot be seen from outside: only a clear tells, and it costs the motor
  the drive's stall-detection time (2 s in the HIL) of stall current, about 3 % of a
  minute.  Gentler retries (a larger ``HealthPolicy.service_retry_s``, not a configuration
  key yet) would leave a freed drive out of service that much longer;
* stow: a drive in STOW because its watchdog fired (COMM_LOST) is resumed once the link is
  back; a STOW the controller commanded is resumed when the weather allows; any other
  STOW (a local wind switch, a maintenance panel, another master) is left alone and
  reported; MAINTENANCE is reported and left alone too;
* a target the drive had to clamp means the controller's limits and the drive's disagree;
* readings that cannot be: an angle far outside the travel or not a number, a jump faster
  than the drive's own speed limit, an axis in AUTO standing still away from its target.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum

from firmware_protocol import Command, Fault, Mode, Status

from .drives.base import DriveState


class Health(str, Enum):
    OK = "ok"
    DEGRADED = "degraded"
    LOST = "lost"


#: How far past its travel an axis may read before the reading is taken for a fault (deg):
#: an overshoot, a backlash, a hand-crank are within it; 1e6 deg or a sentinel are not.
PLAUSIBLE_MARGIN_DEG = 10.0


def implausible_axes(st: DriveState, limits: Sequence[tuple[float, float]]) -> str:
    """What is impossible in the axes' readings (empty when nothing): an angle that is not a
    number or lies more than :data:`PLAUSIBLE_MARGIN_DEG` outside the axis's travel."""
    bad = []
    for k, (a, (lo, hi)) in enumerate(zip(st.axes, limits, strict=False)):
        x = a.actual_deg
        if not (math.isfinite(x) and lo - PLAUSIBLE_MARGIN_DEG <= x <= hi + PLAUSIBLE_MARGIN_DEG):
            bad.append(f"axis {k} reads {x:.2f} deg, outside its travel [{lo:g}, {hi:g}]")
    return "; ".join(bad) + (" (encoder or firmware fault)" if bad else "")


@dataclass(frozen=True)
class HealthPolicy:
    """Thresholds (counts, seconds)."""

    lost_after: int = 3
    max_fault_clears: int = 3
    clear_interval_s: float = 60.0
    service_retry_s: float = 60.0
    fault_free_s: float = 150.0  # more than two periods at the default clear interval
    min_backoff_s: float = 60.0
    max_backoff_s: float = 960.0


@dataclass
class DriveHealth:
    policy: HealthPolicy = field(default_factory=HealthPolicy)
    state: Health = Health.OK
    reason: str = ""
    errors_in_row: int = 0
    fault_clears: int = 0
    last_clear: float = -math.inf
    #: Since when the drive has shown no fault (the clear count restarts after a while).
    fault_free_since: float | None = None
    reconnect_at: float = -math.inf
    backoff_s: float = 0.0
    #: The controller commanded this drive into STOW (weather) and owns its resume.
    stowed_by_us: bool = False
    #: The drive was seen stowed by its own watchdog (COMM_LOST) before a heartbeat
    #: cleared the flag: resume it once the link is back.
    watchdog_stow: bool = False
    #: The drive was last seen in a stow that is not ours (a local switch, another master;
    #: seen in this run or left so by the last shutdown): a COMM_LOST since does not make
    #: it the watchdog's, only the drive's WATCHDOG_STOW latch does.
    foreign_stow: bool = False
    #: When the drive last answered an exchange (the clock's monotonic time, s).
    last_ok: float = -math.inf
    #: RESUMEs sent while the drive stayed stowed (a watchdog stow that does not lift).
    resumes_unanswered: int = 0
    #: Per axis: (the reading it stands still at, since when) while away from its target.
    still: dict[int, tuple[float, float]] = field(default_factory=dict)
    #: Per axis: (the last reading, when, HOMED then): a jump faster than the drive can move
    #: is a fault.
    readings: dict[int, tuple[float, float, bool]] = field(default_factory=dict)

    # -- link -----------------------------------------------------------------------
    def comm_failed(self, now: float, why: str) -> bool:
        """Record a failed cycle; True when the link should be closed and reopened later."""
        self.errors_in_row += 1
        if self.errors_in_row < self.policy.lost_after:
            self.state, self.reason = Health.DEGRADED, why
            return False
        self.state, self.reason = Health.LOST, f"{why} ({self.errors_in_row} failed attempts in a row)"
        self.backoff_s = min(max(2 * self.backoff_s, self.policy.min_backoff_s), self.policy.max_backoff_s)
        self.reconnect_at = now + self.backoff_s
        return True

    def hold(self, why: str) -> None:
        """The drive answers but another party holds it (:class:`DriveHeld`): ``degraded``
        with the reason, and not a link failure (a reconnection would start it again)."""
        self.state, self.reason = Health.DEGRADED, why

    def may_reconnect(self, now: float) -> bool:
        return now >= self.reconnect_at

    # -- what the drive says -----------------------------------------------------------
    def assess(
        self,
        st: DriveState,
        now: float,
        *,
        weather_stow: bool,
        limits: Sequence[tuple[float, float]] = (),
        max_speeds: Sequence[float] = (),
        targets: Sequence[float] = (),
    ) -> list[Command]:
        """Judge a successful exchange; returns the commands to send (CLEAR_FAULT, RESUME).
        ``limits``: each axis's travel (deg), to judge its reading; ``max_speeds``: each
        axis's speed limit as the drive holds it (deg/s), to judge its motion; ``targets``:
        what this exchange commanded (deg), to judge the target the drive works to."""
        self.last_ok = now
        self.errors_in_row = 0
        self.backoff_s = 0.0
        problems: list[str] = []
        commands: list[Command] = []
        faults = [(k, a) for k, a in enumerate(st.axes) if a.status & Status.FAULT]
        lost = False
        if faults:
            self.fault_free_since = None
            names = ", ".join(f"axis {k} {_fault_text(a.fault, a.status)}" for k, a in faults)
            if self.fault_clears < self.policy.max_fault_clears:
                if self._due(now, self.policy.clear_interval_s):
                    commands.append(Command.CLEAR_FAULT)
                    self.fault_clears += 1
                    self.last_clear = now
                problems.append(f"{names} (clear {self.fault_clears}/{self.policy.max_fault_clears})")
            else:
                lost = True
                if self._due(now, self.policy.service_retry_s):
                    commands.append(Command.CLEAR_FAULT)
                    self.fault_clears += 1
                    self.last_clear = now
                problems.append(
                    f"{names} persists or comes back after {self.fault_clears} clears: needs service "
                    f"(next clear in {max(self.last_clear + self.policy.service_retry_s - now, 0.0):.0f} s)"
                )
        elif self.fault_free_since is None:
            self.fault_free_since = now
        elif now - self.fault_free_since >= self.policy.fault_free_s:
            self.fault_clears = 0
        modes = {a.mode for a in st.axes}
        # the watchdog's stow: still without heartbeat, or latched by the drive after it
        latched = any(a.status & Status.WATCHDOG_STOW for a in st.axes)
        comm_lost = latched or (not self.foreign_stow and any(a.status & Status.COMM_LOST for a in st.axes))
        if Mode.MAINTENANCE in modes:
            problems.append("in MAINTENANCE mode (service)")
        if Mode.STOW in modes:
            ours = self.stowed_by_us or self.watchdog_stow or comm_lost
            if ours and not weather_stow and faults:
                problems.append("stowed with a fault latched: resumed once the fault clears")
            elif ours and not weather_stow:
                commands.append(Command.RESUME)  # our stow, or the watchdog's
                self.resumes_unanswered += 1
                if self.resumes_unanswered > 2:  # still stowed after RESUMEs: not lifting
                    problems.append(
                        f"its stow does not lift after {self.resumes_unanswered - 1} RESUMEs"
                        + (" (COMM_LOST still set: heartbeats not accepted?)" if comm_lost else "")
                    )
                self.stowed_by_us = self.watchdog_stow = self.foreign_stow = False
            elif not ours:
                self.foreign_stow = True
                problems.append("stowed by a local switch or another master: left stowed")
        else:
            self.watchdog_stow = self.foreign_stow = False
            self.resumes_unanswered = 0
        wrong = implausible_axes(st, limits)
        if wrong:
            problems.append(wrong)
        problems.extend(self._jumps(st, now, max_speeds))
        problems.extend(_other_targets(st, targets))
        problems.extend(self._not_following(st, now))
        if any(a.status & Status.TARGET_CLAMPED for a in st.axes):
            problems.append("the drive clamped a target (its limits differ from the configuration)")
        if lost:
            self.state = Health.LOST
        elif problems:
            self.state = Health.DEGRADED
        else:
            self.state = Health.OK
        self.reason = "; ".join(problems)
        return commands

    def _jumps(self, st: DriveState, now: float, max_speeds: Sequence[float]) -> list[str]:
        """Axes whose reading moved further since the last one than their speed limit
        allows (with :data:`JUMP_FACTOR` and :data:`JUMP_SLACK_DEG` for timing and
        quantisation): an encoder or firmware fault, or a drive that reports another
        axis's angle.  Not judged across homing (HOMED clear, or just set again): the
        encoder is re-referenced, and its reading may jump by the correction."""
        out = []
        for k, (a, vmax) in enumerate(zip(st.axes, max_speeds, strict=False)):
            homed = bool(a.status & Status.HOMED)
            x0, t0, homed0 = self.readings.get(k, (math.nan, now, homed))
            if math.isfinite(a.actual_deg):
                self.readings[k] = (a.actual_deg, now, homed)
            moved, dt = abs(a.actual_deg - x0), now - t0
            if homed and homed0 and moved > vmax * dt * JUMP_FACTOR + JUMP_SLACK_DEG:
                out.append(
                    f"axis {k} reading jumped {moved:.2f} deg in {dt:.1f} s, faster than its "
                    f"{vmax:g} deg/s (encoder or firmware fault)"
                )
        return out

    def _not_following(self, st: DriveState, now: float) -> list[str]:
        out = []
        for k, a in enumerate(st.axes):
            away = a.mode == Mode.AUTO and abs(a.target_deg - a.actual_deg) > FOLLOW_AWAY_DEG
            x0, t0 = self.still.get(k, (math.nan, now))
            if not away:
                self.still.pop(k, None)  # where it should be (or not ours to move)
            elif not abs(a.actual_deg - x0) <= STILL_DEG:
                self.still[k] = (a.actual_deg, now)  # moving: the clock starts again
            elif now - t0 >= FOLLOW_S:
                out.append(
                    f"axis {k} does not follow its target (at {a.actual_deg:.2f} deg, target "
                    f"{a.target_deg:.2f}, for {now - t0:.0f} s)"
                )
        return out

    def _due(self, now: float, interval: float) -> bool:
        """``interval`` s since the last clear, give or take 5 %: a cycle's exchange a few ms
        early must not put the clear off by a whole period."""
        return now - self.last_clear >= 0.95 * interval


#: An axis in AUTO this far from its target (deg) that has not moved ``FOLLOW_S`` seconds
#: does not follow it (a drive that acknowledges targets and never moves, and sets no
#: STALLED bit); a slew starts within a second, so half a minute is no false alarm.
FOLLOW_AWAY_DEG, FOLLOW_S, STILL_DEG = 1.0, 30.0, 0.01
#: A reading may move ``JUMP_FACTOR`` times the axis's speed limit times the time since the
#: last reading, plus ``JUMP_SLACK_DEG`` (a reading's age within a cycle, a quantum).
JUMP_FACTOR, JUMP_SLACK_DEG = 1.5, 1.0
#: A drive's target may differ from the one commanded by its encoding's rounding (deg).
TARGET_TOLERANCE_DEG = 0.01


def _other_targets(st: DriveState, targets: Sequence[float]) -> list[str]:
    """Axes in AUTO that work to another target than the one just commanded, without saying
    they clamped it (TARGET_CLAMPED), being faulted or homing: a firmware that acknowledges
    set-points and latches others, which the axis then follows as if told to."""
    out = []
    for k, (a, want) in enumerate(zip(st.axes, targets, strict=False)):
        if a.mode != Mode.AUTO or a.status & (Status.TARGET_CLAMPED | Status.FAULT):
            continue
        if not a.status & Status.HOMED:  # homing: the drive works to its index, not to ours
            continue
        if not abs(a.target_deg - want) <= TARGET_TOLERANCE_DEG:
            out.append(
                f"axis {k} works to {a.target_deg:.3f} deg, {want:.3f} commanded (another target latched)"
            )
    return out


def _fault_text(fault: Fault, status: Status) -> str:
    text = f"fault {fault.name}"
    limits = [
        n for n, bit in (("LIMIT_NEG", Status.LIMIT_NEG), ("LIMIT_POS", Status.LIMIT_POS)) if status & bit
    ]
    return text + (f" ({', '.join(limits)})" if limits else "")
