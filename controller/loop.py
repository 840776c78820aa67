"""The control loop: one cycle = sun estimate -> mode -> setpoints -> drives -> record."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from firmware_protocol import Command, Mode, Status

from .clock import Clock
from .config import Config, TrackerConfig
from .drives import DriveCommError, DriveLink, DriveState
from .geometry import dual_axis_setpoint, single_axis_setpoint
from .modes import ControlMode, ModeDecision, decide_mode
from .sun.source import SunSource
from .sun.types import SunEstimate


@dataclass
class CycleRecord:
    """What happened to one tracker in one cycle (degrees; time in POSIX seconds)."""

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
    backtracking: bool = False
    error: str = ""


@dataclass
class TrackerRuntime:
    cfg: TrackerConfig
    drive: DriveLink
    last_targets: tuple[float, ...] = ()
    last_state: DriveState | None = None
    errors: int = 0


class Controller:
    """Drives every configured tracker from one sun source.

    A failing drive is recorded and skipped for that cycle; it never stops the others.
    """

    def __init__(self, config: Config, drives: Mapping[str, DriveLink], sun: SunSource,
                 clock: Clock):
        self.config = config
        self.sun = sun
        self.clock = clock
        self.trackers = [TrackerRuntime(t, drives[t.name]) for t in config.trackers]
        self.cycles = 0

    # -- start-up -----------------------------------------------------------------
    def start(self) -> None:
        """Connect and configure every drive (limits, stow angles, watchdog)."""
        for tr in self.trackers:
            tr.drive.connect()
            if tr.drive.axis_count < tr.cfg.axes:
                raise DriveCommError(f"{tr.cfg.name}: drive has {tr.drive.axis_count} axis, "
                                     f"a {tr.cfg.type} tracker needs {tr.cfg.axes}")
            tr.drive.configure(heartbeat_timeout_s=self.config.control.heartbeat_timeout_s,
                               soft_limits=tr.cfg.soft_limits, stow_angles=tr.cfg.stow)
            tr.drive.heartbeat()
            self._resume_if_stowed(tr)

    def _resume_if_stowed(self, tr: TrackerRuntime) -> None:
        state = tr.drive.read_state()
        tr.last_state = state
        if any(a.mode == Mode.STOW for a in state.axes):
            tr.drive.command(Command.RESUME)

    # -- one cycle ----------------------------------------------------------------
    def cycle(self) -> list[CycleRecord]:
        t = self.clock.now()
        aim_t = t + self.config.control.lead_s
        est = self.sun.estimate(aim_t)
        decision = (decide_mode(est.el_deg, self.config.control.min_elevation_deg)
                    if est is not None else ModeDecision(ControlMode.STOW, "no sun estimate"))
        records = [self._drive_one(tr, t, est, decision) for tr in self.trackers]
        self.cycles += 1
        return records

    def _drive_one(self, tr: TrackerRuntime, t: float, est: SunEstimate | None,
                   decision: ModeDecision) -> CycleRecord:
        rec = CycleRecord(
            time=t, tracker=tr.cfg.name, mode=decision.mode.value, reason=decision.reason,
            source=est.source.value if est else "none",
            sun_az_deg=est.az_deg if est else math.nan, sun_el_deg=est.el_deg if est else math.nan)
        try:
            targets, rec.backtracking = self.setpoint(tr, est, decision)
            tr.drive.heartbeat()
            tr.drive.write_targets(targets)
            state = tr.drive.read_state()
            if any(a.mode == Mode.STOW and a.status & Status.COMM_LOST for a in state.axes) \
                    or (decision.mode != ControlMode.STOW and any(a.mode == Mode.STOW for a in state.axes)):
                # The firmware stowed itself (watchdog); the link is alive again: resume.
                tr.drive.command(Command.RESUME)
            tr.last_targets, tr.last_state = tuple(targets), state
            rec.targets_deg = tuple(targets)
            rec.actual_deg = tuple(a.actual_deg for a in state.axes)
            rec.status = int(state.device_status)
        except DriveCommError as exc:
            tr.errors += 1
            rec.error = str(exc)
        return rec

    def setpoint(self, tr: TrackerRuntime, est: SunEstimate | None,
                 decision: ModeDecision) -> tuple[list[float], bool]:
        """Axis targets (deg) for a tracker, and whether the row is backtracking."""
        cfg = tr.cfg
        if decision.mode == ControlMode.STOW or est is None:
            return list(cfg.stow), False
        if cfg.type == "dual-axis":
            current = tr.last_state.axes[0].actual_deg if tr.last_state else None
            az, el = dual_axis_setpoint(est.az_deg, est.el_deg, cfg.azimuth_limits,
                                        cfg.elevation_limits, current)
            return [az, el], False
        sp = single_axis_setpoint(est.az_deg, est.el_deg, axis_azimuth=cfg.axis_azimuth,
                                  axis_tilt=cfg.axis_tilt, max_angle=cfg.max_angle, gcr=cfg.gcr,
                                  cross_axis_tilt=cfg.cross_axis_tilt, backtrack=cfg.backtrack)
        if math.isnan(sp.rotation_deg):  # sun below the horizon but inside the wake margin
            return list(cfg.stow), False
        return [sp.rotation_deg], sp.backtracking

    def stats(self) -> dict:
        tx = sum(tr.drive.stats.transactions for tr in self.trackers)
        err = sum(tr.drive.stats.errors for tr in self.trackers)
        return {"transactions": tx, "errors": err,
                "retries": sum(tr.drive.stats.retries for tr in self.trackers)}

    def close(self) -> None:
        for tr in self.trackers:
            try:
                tr.drive.close()
            except Exception:
                pass
