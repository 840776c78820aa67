"""The control loop: one cycle = sun estimate -> mode -> setpoints -> drives -> record.

All trackers are served concurrently (asyncio) under one deadline per cycle, so a dead
or slow drive costs its own row that cycle and never delays the others.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass

from firmware_protocol import Command, Mode

from .clock import Clock
from .config import Config, DualAxisTracker, SingleAxisTracker, TrackerConfig
from .drives import DriveCommError, DriveLink, DriveState
from .geometry import dual_axis_setpoint, single_axis_setpoints, wrap_into_range
from .diffuse import DiffuseSwitch
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
    latency_s: float = 0.0   # wall time from the cycle's start until this row was done


@dataclass
class TrackerRuntime:
    cfg: TrackerConfig
    drive: DriveLink
    last_targets: tuple[float, ...] = ()
    last_state: DriveState | None = None
    last_heartbeat: float = -math.inf
    configured: bool = False
    index: int = 0
    start_error: str = ""
    errors: int = 0


class Controller:
    """Drives every configured tracker from one sun source.

    A failing drive is recorded and skipped for that cycle; it never stops the others.
    """

    def __init__(self, config: Config, drives: Mapping[str, DriveLink], sun: SunSource,
                 clock: Clock, realtime: bool = False, pyranometer=None, sensor=None):
        self.config = config
        self.realtime = realtime
        self.pyranometer = pyranometer
        self.sensor = sensor          # a camera sun sensor feeding ``sun`` (sun-path filter)
        self._saved_day: int | None = None
        self._last_el_deg = math.inf
        self._last_frame_t = -math.inf
        self.diffuse = DiffuseSwitch(config.site, config.diffuse)
        self.sensor_errors = 0
        #: Operator overrides by tracker index: manual axis targets (deg) in force.
        self.overrides: dict[int, tuple[float, ...]] = {}
        self._home_requested: set[int] = set()
        self.sun = sun
        self.clock = clock
        self.trackers = [TrackerRuntime(t, drives[t.name]) for t in config.trackers]
        self.cycles = 0

    # -- start-up -----------------------------------------------------------------
    async def start(self) -> None:
        """Connect and configure every drive (limits, stow angles, watchdog).

        A drive that fails here is recorded and retried by the next cycles; the others
        start regardless.
        """
        for index, tr in enumerate(self.trackers):
            tr.index = index
        await asyncio.gather(*(self._start_one(tr) for tr in self.trackers))

    #: Time budget for connecting and configuring one drive at start-up (s): SDO
    #: configuration of a hundred drives on one CAN bus takes seconds, not a cycle.
    START_TIMEOUT_S = 60.0

    async def _start_one(self, tr: TrackerRuntime) -> None:
        try:
            await asyncio.wait_for(self._configure(tr), self.START_TIMEOUT_S)
        except (DriveCommError, asyncio.TimeoutError) as exc:
            tr.errors += 1
            tr.start_error = str(exc) or "timeout"

    async def _configure(self, tr: TrackerRuntime) -> None:
        await tr.drive.connect()
        if tr.drive.axis_count < tr.cfg.axes:
            raise DriveCommError(f"{tr.cfg.name}: drive has {tr.drive.axis_count} axis, "
                                 f"a {tr.cfg.type} tracker needs {tr.cfg.axes}")
        await tr.drive.configure(heartbeat_timeout_s=self.config.control.heartbeat_timeout_s,
                                 soft_limits=tr.cfg.soft_limits, stow_angles=tr.cfg.stow_angles)
        await self._heartbeat(tr, force=True)
        # Spread the rows' heartbeats over the interval so they do not all fall on one cycle.
        tr.last_heartbeat -= (tr.index % 3) * self.config.control.heartbeat_timeout_s / 9
        tr.configured = True

    def _deadline(self) -> float:
        """Per-tracker time budget for one cycle (s of wall time)."""
        return max(0.8 * self.config.control.period_s, 0.2) if self.realtime else 30.0

    async def _heartbeat(self, tr: TrackerRuntime, force: bool = False) -> None:
        # Three heartbeats per watchdog timeout are plenty and spare the bus.
        t = self.clock.now()
        timeout = self.config.control.heartbeat_timeout_s
        if force or timeout <= 0 or t - tr.last_heartbeat >= timeout / 3 - 1e-9:
            await tr.drive.heartbeat()
            tr.last_heartbeat = t

    # -- one cycle ----------------------------------------------------------------
    async def cycle(self) -> list[CycleRecord]:
        t = self.clock.now()
        aim_t = t + self.config.control.lead_s
        await self._observe(t)
        est = self.sun.estimate(aim_t, now=t)
        self._last_el_deg = est.el_deg if est is not None else math.inf
        overcast = await self._sky(t)
        decision = (decide_mode(est.el_deg, self.config.control.min_elevation_deg,
                                overcast=overcast)
                    if est is not None else ModeDecision(ControlMode.STOW, "no sun estimate"))
        setpoints = self.setpoints(est, decision)
        t_wall = time.perf_counter()
        records = [self._record(tr, t, est, decision, sp)
                   for tr, sp in zip(self.trackers, setpoints)]
        safety_stow = (decision.mode == ControlMode.STOW
                       and decision.reason not in ("night", "no sun estimate"))
        for i, targets in ({} if safety_stow else self.overrides).items():
            # An operator's manual setpoint outranks tracking, DIFFUSE and night stow,
            # never a safety stow.
            setpoints[i] = (list(targets), False)
            records[i].mode, records[i].reason = ControlMode.MANUAL.value, "operator override"
        tasks = [asyncio.ensure_future(self._drive_one(tr, rec, sp[0], decision, t_wall))
                 for tr, rec, sp in zip(self.trackers, records, setpoints)]
        # One deadline for the cycle: a row still waiting then is cancelled and marked;
        # the others have long finished, so a dead drive costs only its own row.
        _, late = await asyncio.wait(tasks, timeout=self._deadline())
        for task in late:
            task.cancel()
        if late:
            await asyncio.wait(late)
        for tr, rec, task in zip(self.trackers, records, tasks):
            if not task.cancelled() and task.exception() is not None:
                # A bug or an unexpected library error: recorded for this row, not hidden.
                exc = task.exception()
                tr.errors += 1
                rec.error = f"{tr.cfg.name}: {type(exc).__name__}: {exc}"
                rec.latency_s = time.perf_counter() - t_wall
            elif not rec.latency_s:
                tr.errors += 1
                rec.error = f"{tr.cfg.name}: no answer within {self._deadline():g} s"
                rec.latency_s = time.perf_counter() - t_wall
        self.cycles += 1
        return records

    async def _observe(self, t: float) -> None:
        """Feed the sun-path filter from the camera (in a thread: frames take time).

        One frame per ``[hotspot] interval_s`` (every cycle when 0); skipped while the last
        estimate put the sun well below the horizon.
        """
        if self.sensor is None:
            return
        interval = self.config.hotspot.interval_s if self.config.hotspot is not None else 0.0
        if self._last_el_deg >= -5.0 and t - self._last_frame_t >= interval - 1e-6:
            self._last_frame_t = t
            obs = await asyncio.to_thread(self.sensor.observe, t)
            if obs is not None:
                self.sun.observe(obs)
        day = int(t // 86400)
        if self._saved_day is not None and day != self._saved_day:
            self._save_sun_state()
        self._saved_day = day

    def _save_sun_state(self) -> None:
        self.sun.save()   # atomic; once a day and at shutdown

    async def _sky(self, t: float) -> bool:
        """Sample the pyranometer and ask the DIFFUSE switch; a bad sample is skipped."""
        if self.pyranometer is None or not self.config.diffuse.enabled:
            return False
        try:
            sample = await asyncio.wait_for(self.pyranometer.read(t), self._deadline())
            self.diffuse.add(sample.time, sample.ghi_w_m2)
        except (DriveCommError, asyncio.TimeoutError):
            self.sensor_errors += 1
        return self.diffuse.update(t)

    @staticmethod
    def _record(tr: TrackerRuntime, t: float, est: SunEstimate | None, decision: ModeDecision,
                setpoint: tuple[list[float], bool]) -> CycleRecord:
        return CycleRecord(
            time=t, tracker=tr.cfg.name, mode=decision.mode.value, reason=decision.reason,
            source=est.source.value if est else "none",
            sun_az_deg=est.az_deg if est else math.nan,
            sun_el_deg=est.el_deg if est else math.nan, backtracking=setpoint[1])

    async def _drive_one(self, tr: TrackerRuntime, rec: CycleRecord, targets: list[float],
                         decision: ModeDecision, t_wall: float) -> None:
        try:
            state = await self._exchange(tr, targets, decision)
            rec.targets_deg = tuple(targets)
            rec.actual_deg = tuple(a.actual_deg for a in state.axes)
            rec.status = int(state.device_status)
        except DriveCommError as exc:
            tr.errors += 1
            rec.error = str(exc)
        rec.latency_s = time.perf_counter() - t_wall

    async def _exchange(self, tr: TrackerRuntime, targets: list[float],
                        decision: ModeDecision) -> DriveState:
        if not tr.configured:
            await self._configure(tr)
        await self._heartbeat(tr)
        if tr.index in self._home_requested:
            await tr.drive.command(Command.HOME)
            self._home_requested.discard(tr.index)
        state = await tr.drive.exchange(targets)
        if decision.mode != ControlMode.STOW and any(a.mode == Mode.STOW for a in state.axes):
            # The firmware stowed itself (watchdog) and the link is alive again: resume.
            await self._heartbeat(tr, force=True)
            await tr.drive.command(Command.RESUME)
        tr.last_targets, tr.last_state = tuple(targets), state
        return state

    def setpoints(self, est: SunEstimate | None, decision: ModeDecision
                  ) -> list[tuple[list[float], bool]]:
        """Axis targets (deg) for every tracker, and whether each row is backtracking.

        Single-axis rows are computed together in one vectorised call.
        """
        out: list[tuple[list[float], bool]] = [(list(tr.cfg.stow_angles), False)
                                               for tr in self.trackers]
        if decision.mode == ControlMode.STOW or est is None:
            return out
        if decision.mode == ControlMode.DIFFUSE:
            return [self._facing_sky(tr) for tr in self.trackers]
        rows = [(i, tr.cfg) for i, tr in enumerate(self.trackers)
                if isinstance(tr.cfg, SingleAxisTracker)]
        if rows:
            sps = single_axis_setpoints(est.az_deg, est.el_deg, [cfg for _, cfg in rows])
            for (i, _), sp in zip(rows, sps):
                if not math.isnan(sp.rotation_deg):  # NaN: sun still below the horizon
                    out[i] = ([sp.rotation_deg], sp.backtracking)
        for i, tr in enumerate(self.trackers):
            cfg = tr.cfg
            if isinstance(cfg, DualAxisTracker):
                current = tr.last_state.axes[0].actual_deg if tr.last_state else None
                az, el = dual_axis_setpoint(est.az_deg, est.el_deg, cfg.azimuth_limits,
                                            cfg.elevation_limits, current)
                out[i] = ([az, el], False)
        return out

    def set_override(self, tracker: int | None, ctl: str, el_deg: float | None,
                     az_deg: float | None) -> None:
        """Apply an operator command (SunSpec model 601 semantics).

        ``ctl``: "Automatic" clears the override, "Manual" holds the given setpoint
        (dual-axis: elevation and azimuth; single-axis: the rotation in ``el_deg``; a
        missing value keeps the axis where it is), "Calibrate" re-homes the drives.
        ``tracker`` None applies to every tracker.
        """
        indices = range(len(self.trackers)) if tracker is None else [tracker]
        for i in indices:
            tr = self.trackers[i]
            cfg = tr.cfg
            if ctl == "Automatic":
                self.overrides.pop(i, None)
            elif ctl == "Calibrate":
                self._home_requested.add(i)
            elif ctl == "Manual":
                now = tr.last_state.axes if tr.last_state else None
                if isinstance(cfg, SingleAxisTracker):
                    rot = el_deg if el_deg is not None else (now[0].actual_deg if now else cfg.stow)
                    self.overrides[i] = (min(max(rot, -cfg.max_angle), cfg.max_angle),)
                elif isinstance(cfg, DualAxisTracker):
                    az = az_deg if az_deg is not None else (now[0].actual_deg if now else cfg.stow[0])
                    el = el_deg if el_deg is not None else (now[1].actual_deg if now else cfg.stow[1])
                    az = wrap_into_range(az, *cfg.azimuth_limits,
                                         near=now[0].actual_deg if now else None)
                    lo, hi = cfg.elevation_limits
                    self.overrides[i] = (az, min(max(el, lo), hi))
            else:
                raise ValueError(f"unknown control {ctl!r}")

    @staticmethod
    def _facing_sky(tr: TrackerRuntime) -> tuple[list[float], bool]:
        """Flat: the panel faces the zenith and sees the whole overcast dome."""
        cfg = tr.cfg
        if not isinstance(cfg, DualAxisTracker):
            return [0.0], False
        az = tr.last_state.axes[0].actual_deg if tr.last_state else cfg.stow[0]
        el = min(90.0, cfg.elevation_limits[1])
        return [az, el], False

    async def run(self, duration_s: float, on_cycle=None) -> dict:
        """Cycle on period boundaries of ``self.clock`` for ``duration_s``.

        ``on_cycle(records)`` is called after every cycle.  A cycle that overruns its
        period makes the loop skip to the next boundary (counted in ``overruns``) rather
        than queue late cycles.
        """
        period = self.config.control.period_s
        t_end = self.clock.now() + duration_s
        next_t = self.clock.now()
        overruns = 0
        while next_t < t_end:
            delay = max(next_t - self.clock.now(), 0.0)
            if self.realtime:
                await asyncio.sleep(delay)   # keep the event loop (other rows, servers) alive
            else:
                self.clock.sleep(delay)
            records = await self.cycle()
            if on_cycle is not None:
                on_cycle(records)
            next_t += period
            while self.clock.now() > next_t:
                next_t += period
                overruns += 1
        return {"cycles": self.cycles, "overruns": overruns}

    def stats(self) -> dict:
        tx = sum(tr.drive.stats.transactions for tr in self.trackers)
        err = sum(tr.drive.stats.errors for tr in self.trackers)
        return {"transactions": tx, "errors": err,
                "retries": sum(tr.drive.stats.retries for tr in self.trackers),
                "sensor_errors": self.sensor_errors}

    async def close(self) -> None:
        if self.sensor is not None:
            self._save_sun_state()
        if self.pyranometer is not None:
            await self.pyranometer.close()
        for tr in self.trackers:
            try:
                await tr.drive.close()
            except Exception:  # closing a dead link must not hide the real error
                pass
