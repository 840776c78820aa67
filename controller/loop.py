"""The control loop: one cycle = sun estimate -> mode -> setpoints -> drives -> record.

All trackers are served concurrently (asyncio) under one deadline per cycle, so a dead
or slow drive costs its own row that cycle and never delays the others.  Priorities: the
drives' own watchdog, then a weather stow (wind, hail, snow: :mod:`controller.safety`),
then an operator's manual setpoint, night stow, DIFFUSE and tracking.  Wind is polled
between cycles (:meth:`Controller.poll_weather`) and stows every drive at once.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

from firmware_protocol import Command, Mode

from . import setpoints as sp
from .clock import Clock
from .config import Config
from .diffuse import DiffuseSwitch
from .drive_setup import DriveSetup
from .drives.base import DriveCommError, DriveHeld, DriveLink, DriveState
from .geometry import lowest_sun_azimuth
from .health import Health
from .history import History
from .modes import ControlMode, ModeDecision, decide_mode
from .records import CycleRecord, TrackerRuntime
from .safety import SafetyState, StowOrder, clamp_targets
from .sky.daylight import DaylightCheck
from .store import Store
from .sun.source import SunSource
from .sun.types import SunEstimate
from .wind_polling import WindPolling, WindSensor

log = logging.getLogger("heliotrack.controller")

__all__ = ["Controller", "CycleRecord", "TrackerRuntime"]


def sun_alarm_text(learned: dict) -> str:
    """The SUN ALARM's text from a sun source's ``summary()`` that reports a site mismatch:
    the sky's offset from the configured site and, when the filter names one, the likely
    mistake (a sign, or time stamps in another zone)."""
    cause = learned.get("site_mismatch_cause") or "check the site and the clock"
    return (
        f"sky and configured site disagree (latitude "
        f"{learned.get('site_mismatch_lat_deg', learned.get('site_offset_lat_deg', 0.0)):+.2f} deg, "
        f"longitude {learned.get('site_mismatch_lon_deg', learned.get('site_offset_lon_deg', 0.0)):+.2f} "
        f"deg): {cause}"
    )


class LinkDownError(DriveCommError):
    """The drive's link is closed and waits for its reconnection time: nothing was tried, so
    nothing failed again (the backoff does not grow, the reason is not wrapped anew)."""


class Controller(WindPolling, DriveSetup):
    """Drives every configured tracker from one sun source.

    A failing drive is recorded and skipped for that cycle; it never stops the others.

    Parameters
    ----------
    config : the plant
    drives : tracker name -> drive link (not yet connected)
    sun : the sun source
    clock : wall-clock time for records and the sun (a simulated clock in the HIL)
    realtime : pace :meth:`run` on the event loop's monotonic clock
    pyranometer, anemometer : sensors (or None)
    sensor : a camera sun sensor feeding ``sun``
    """

    #: Time budget for connecting and configuring one drive at start-up (s): SDO
    #: configuration of a hundred drives on one CAN bus takes seconds, not a cycle.
    START_TIMEOUT_S = 60.0

    def __init__(
        self,
        config: Config,
        drives: Mapping[str, DriveLink],
        sun: SunSource,
        clock: Clock,
        realtime: bool = False,
        pyranometer: Any = None,
        sensor: Any = None,
        anemometer: WindSensor | None = None,
        store: Store | None = None,
    ):
        self.config = config
        self.realtime = realtime
        self.pyranometer = pyranometer
        self.anemometer = anemometer
        self.sensor = sensor  # a camera sun sensor feeding ``sun`` (sun-path filter)
        self.history = History(store, config.store.history_days) if store is not None else None
        if store is not None:
            sun.use_store(store, clock.now())
        self._saved_day: int | None = None
        self._last_el_deg = math.inf
        self._next_wind_poll = -math.inf
        self.diffuse = DiffuseSwitch(config.site, config.diffuse)
        self.sensor_errors = 0
        #: Sensors not answering now, by name, with why (one warning per outage).
        self.sensors_down: dict[str, str] = {}
        self.sun_alarm = ""
        self.daylight = DaylightCheck(config.site)
        self.safety = SafetyState(config.wind, config.stow, clock.now(), warn=log.warning)
        #: Operator overrides by tracker index: manual axis targets (deg) in force.
        self.overrides: dict[int, tuple[float, ...]] = {}
        self._home_requested: set[int] = set()
        self.sun = sun
        self.clock = clock
        self.trackers = [TrackerRuntime(t, drives[t.name], index=i) for i, t in enumerate(config.trackers)]
        self.cycles = 0
        #: Machine-readable events (weather stow and resume, health changes), newest last.
        self.events: deque[dict[str, Any]] = deque(maxlen=10_000)

    # -- start-up -----------------------------------------------------------------
    def _deadline(self) -> float:
        """Per-tracker time budget for one cycle (s of wall time)."""
        return max(0.8 * self.config.control.period_s, 0.2) if self.realtime else 30.0

    # -- one cycle ----------------------------------------------------------------
    async def cycle(self) -> list[CycleRecord]:
        t = self.clock.now()
        aim_t = t + self.config.control.lead_s
        await self._observe(t)
        self._daily(t)
        est = self.sun.estimate(aim_t, now=t)
        self._last_el_deg = est.el_deg if est is not None else math.inf
        overcast = await self._sky(t)
        await self._poll_weather_if_due()
        self.safety.read_flag()
        order = self.safety.order()
        decision = self.decide(est, overcast, order)
        targets = self.targets(est, decision, order)
        t_wall = time.perf_counter()
        alarms = tuple(self.safety.alarms) + tuple(a for a in (self.sun_alarm, self.daylight.alarm) if a)
        records = [self._record(tr, t, est, decision, s, alarms) for tr, s in zip(self.trackers, targets)]
        if order is None:
            for i, manual in self.overrides.items():
                # An operator's manual setpoint outranks tracking, DIFFUSE and night stow,
                # never a weather stow.
                targets[i] = (list(manual), False)
                records[i].mode, records[i].reason = ControlMode.MANUAL.value, "operator override"
        tasks = [
            asyncio.ensure_future(self._drive_one(tr, rec, s[0], order, t_wall))
            for tr, rec, s in zip(self.trackers, records, targets)
        ]
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
                self._link_failed(tr, rec.error)  # three in a row: a fresh link (a library's stuck state)
            elif not rec.latency_s:
                tr.errors += 1
                rec.error = (
                    f"{tr.cfg.name}: exchange not done within the cycle's {self._deadline():g} s "
                    "(no answer, or answers and retries slower than the period allows)"
                )
                rec.latency_s = time.perf_counter() - t_wall
                self._link_failed(tr, rec.error)
            rec.health, rec.health_reason = tr.health.state.value, tr.health.reason
        if self.history is not None:
            self.history.add_cycle(records)
        self.cycles += 1
        return records

    def decide(self, est: SunEstimate | None, overcast: bool, order: StowOrder | None) -> ModeDecision:
        """The plant's mode this cycle (a weather stow outranks everything)."""
        if order is not None:
            return ModeDecision(ControlMode.STOW, order.reason)
        if est is None or not (math.isfinite(est.az_deg) and math.isfinite(est.el_deg)):
            return ModeDecision(ControlMode.STOW, "no sun estimate")
        return decide_mode(est.el_deg, self.config.control.min_elevation_deg, overcast=overcast)

    def targets(
        self, est: SunEstimate | None, decision: ModeDecision, order: StowOrder | None
    ) -> list[sp.Setpoint]:
        """Axis targets (deg) of every tracker, and whether each row is backtracking."""
        if order is not None:
            return [(list(self.safety.angles(tr.cfg, order.kind)), False) for tr in self.trackers]
        return sp.for_mode(
            decision.mode,
            est,
            [tr.cfg for tr in self.trackers],
            [tr.last_state for tr in self.trackers],
            lowest_sun_azimuth(self.config.site.latitude),
        )

    async def _observe(self, t: float) -> None:
        """Feed the sun-path filter from the camera(s) (in a thread: frames take time).

        Each camera looks once per its ``interval_s`` (every cycle when 0), and every
        observation goes to the filter with its own sigma; skipped while the last estimate
        put the sun well below the horizon.
        """
        if self.sensor is None or self._last_el_deg < -5.0:
            return
        for obs in await asyncio.to_thread(self.sensor.observations, t):
            accepted = self.sun.observe(obs)
            if self.history is not None:
                self.history.add_observation(obs, accepted)
            self._check_sun_site()

    def _daily(self, t: float) -> None:
        """Once a day: save what the sun source learned (atomically), rotate the history."""
        day = int(t // 86400)
        if self._saved_day is not None and day != self._saved_day:
            self.sun.save()
            if self.history is not None:
                self.history.rotate(t)
        self._saved_day = day

    def _check_sun_site(self) -> None:
        """Alarm once when the sky and the configured site disagree by more than the sun-path
        filter allows (a wrong site, or a wall clock off by a time step): the filter keeps the
        configured site and rejects the camera, and only an operator can tell which is wrong."""
        learned = self.sun.summary()
        mismatch = bool(learned.get("site_mismatch"))
        if mismatch and not self.sun_alarm:
            self.sun_alarm = sun_alarm_text(learned)
            log.warning("SUN ALARM: %s", self.sun_alarm)
            self._event("sun_alarm", reason=self.sun_alarm)
        elif not mismatch:
            self.sun_alarm = ""

    def _check_daylight(self, t: float, ghi_w_m2: float) -> None:
        """Alarm once when the pyranometer sees daylight while the configured site and clock
        put the sun below the horizon (:mod:`controller.sky.daylight`)."""
        before = self.daylight.alarm
        if self.daylight.add(t, ghi_w_m2) and not before:
            log.warning("SITE ALARM: %s", self.daylight.alarm)
            self._event("site_alarm", reason=self.daylight.alarm)

    async def _sky(self, t: float) -> bool:
        """Sample the pyranometer and ask the DIFFUSE switch; a bad sample is skipped."""
        if self.pyranometer is None or not self.config.diffuse.enabled:
            return False
        try:
            sample = await asyncio.wait_for(self.pyranometer.read(t), self._deadline())
            self.diffuse.add(sample.time, sample.ghi_w_m2)
            self._sensor_status("pyranometer", None)
            self._check_daylight(sample.time, sample.ghi_w_m2)
        except (TimeoutError, DriveCommError) as exc:
            self._sensor_status("pyranometer", exc)
        return self.diffuse.update(t)

    def _sensor_status(self, name: str, exc: BaseException | None) -> None:
        """Count a failed read; warn once when a sensor stops answering and say once when
        it is back, not on every read."""
        if exc is None:
            if self.sensors_down.pop(name, None) is not None:
                log.info("%s: answering again", name)
            return
        self.sensor_errors += 1
        why = str(exc) or "no answer"
        if name not in self.sensors_down:
            log.warning("%s: %s", name, why)
            self._event("sensor_down", sensor=name, reason=why)
        self.sensors_down[name] = why

    def _event(self, kind: str, **detail: Any) -> None:
        self.events.append({"time": self.clock.now(), "kind": kind, **detail})

    # -- one drive ------------------------------------------------------------------
    def _record(
        self,
        tr: TrackerRuntime,
        t: float,
        est: SunEstimate | None,
        decision: ModeDecision,
        setpoint: sp.Setpoint,
        alarms: tuple[str, ...],
    ) -> CycleRecord:
        return CycleRecord(
            time=t,
            tracker=tr.cfg.name,
            mode=decision.mode.value,
            reason=decision.reason,
            source=est.source.value if est else "none",
            sun_az_deg=est.az_deg if est else math.nan,
            sun_el_deg=est.el_deg if est else math.nan,
            backtracking=setpoint[1],
            alarms=alarms,
        )

    async def _drive_one(
        self,
        tr: TrackerRuntime,
        rec: CycleRecord,
        targets: list[float],
        order: StowOrder | None,
        t_wall: float,
    ) -> None:
        try:
            targets = clamp_targets(tr.cfg, targets)
            state = await self._exchange(tr, targets, order)
            rec.targets_deg = tuple(targets)
            rec.actual_deg = tuple(a.actual_deg for a in state.axes)
            rec.status = int(state.device_status)
            rec.axis_modes = tuple(a.mode.name for a in state.axes)
        except DriveCommError as exc:
            tr.errors += 1
            rec.error = str(exc)
            if not isinstance(exc, LinkDownError):
                self._link_failed(tr, str(exc), held=isinstance(exc, DriveHeld))
        rec.latency_s = time.perf_counter() - t_wall

    def _link_failed(self, tr: TrackerRuntime, why: str, held: bool = False) -> None:
        before = tr.health.state
        if held:
            tr.health.hold(why)
        elif tr.health.comm_failed(self.clock.monotonic(), why) and tr.configured:
            tr.configured = False  # reconnect (and reconfigure) after the backoff
            asyncio.ensure_future(self._close_quietly(tr.drive))
        if tr.health.state != before:
            log.warning("%s: %s: %s", tr.cfg.name, tr.health.state.value, tr.health.reason)
            self._event("health", tracker=tr.cfg.name, state=tr.health.state.value, reason=tr.health.reason)

    @staticmethod
    async def _close_quietly(drive: DriveLink) -> None:
        try:
            await drive.close()
        except Exception:  # noqa: BLE001 - closing a dead link must not hide the real error
            pass

    async def _exchange(
        self, tr: TrackerRuntime, targets: list[float], order: StowOrder | None
    ) -> DriveState:
        if not tr.configured:
            now = self.clock.monotonic()
            if tr.health.may_reconnect(now):
                await self._configure(tr)
            elif await tr.drive.probe():  # answers again: no need to wait out the backoff
                await self._configure(tr, connected=True)
            else:
                raise LinkDownError(
                    f"{tr.cfg.name}: link down ({tr.health.reason}); probed, no answer; next "
                    f"full attempt in {tr.health.reconnect_at - now:.0f} s"
                )
        elif tr.health.errors_in_row or (
            self.clock.monotonic() - tr.last_heartbeat >= 0.9 * self.config.control.heartbeat_timeout_s
        ):
            # Back after failures or a stall: the watchdog may have fired; look before the
            # heartbeat clears its COMM_LOST flag.
            self._note_watchdog_stow(tr, await tr.drive.read_state(), self._unheard(tr))
        await self._heartbeat(tr)
        if tr.index in self._home_requested and self._may_home(tr, order):
            await tr.drive.command(Command.HOME)
            tr.health.readings.clear()  # homing re-references the encoder: its reading may jump
            self._home_requested.discard(tr.index)
        state = await tr.drive.exchange(targets)
        await self._check_restart(tr)
        wind = order is not None and order.kind == "wind"
        if wind and any(a.mode not in (Mode.STOW, Mode.MAINTENANCE) for a in state.axes):
            await tr.drive.command(Command.STOW)  # a drive the fast path missed
            tr.health.stowed_by_us = True
        before = tr.health.state
        held = tr.drive.configuration
        for cmd in tr.health.assess(
            state,
            self.clock.monotonic(),
            weather_stow=wind,
            limits=tr.cfg.soft_limits,
            max_speeds=held.max_speeds if held is not None else (),
            targets=targets,
        ):
            if cmd == Command.RESUME:
                await self._heartbeat(tr, force=True)
            await tr.drive.command(cmd)
        if tr.health.state != before:
            level = logging.INFO if tr.health.state == Health.OK else logging.WARNING
            log.log(
                level,
                "%s: %s%s",
                tr.cfg.name,
                tr.health.state.value,
                f": {tr.health.reason}" if tr.health.reason else "",
            )
            self._event("health", tracker=tr.cfg.name, state=tr.health.state.value, reason=tr.health.reason)
        tr.last_targets, tr.last_state = tuple(targets), state
        return state

    @staticmethod
    def _may_home(tr: TrackerRuntime, order: StowOrder | None) -> bool:
        """A "Calibrate" waits for any stow to end: homing drives the axis to its index, out
        of the stow (a weather order in force, or a drive last seen stowed by anyone)."""
        held = tr.last_state is not None and any(
            a.mode in (Mode.STOW, Mode.MAINTENANCE) for a in tr.last_state.axes
        )
        return order is None and not held

    # -- operator -------------------------------------------------------------------
    def set_override(self, tracker: int | None, ctl: str, el_deg: float | None, az_deg: float | None) -> None:
        """Apply an operator command (SunSpec model 601 semantics).

        ``ctl``: "Automatic" clears the override, "Manual" holds the given setpoint
        (dual-axis: elevation and azimuth; single-axis: the rotation in ``el_deg``; a
        missing value keeps the axis where it is), "Calibrate" re-homes the drives.
        ``tracker`` None applies to every tracker.
        """
        indices = range(len(self.trackers)) if tracker is None else [tracker]
        for i in indices:
            tr = self.trackers[i]
            if ctl == "Automatic":
                self.overrides.pop(i, None)
            elif ctl == "Calibrate":
                self._home_requested.add(i)
            elif ctl == "Manual":
                self.overrides[i] = sp.manual(tr.cfg, tr.last_state, el_deg, az_deg)
            else:
                raise ValueError(f"unknown control {ctl!r}")

    # -- running ----------------------------------------------------------------------
    async def run(
        self,
        duration_s: float,
        on_cycle: Callable[[list[CycleRecord]], Any] | None = None,
        stop: asyncio.Event | None = None,
    ) -> dict[str, int]:
        """Cycle on period boundaries for ``duration_s`` (or until ``stop`` is set); see
        :func:`controller.schedule.run_cycles`."""
        from .schedule import run_cycles

        return await run_cycles(self, duration_s, on_cycle, stop)

    def stats(self) -> dict[str, int]:
        tx = sum(tr.drive.stats.transactions for tr in self.trackers)
        err = sum(tr.drive.stats.errors for tr in self.trackers)
        return {
            "transactions": tx,
            "errors": err,
            "retries": sum(tr.drive.stats.retries for tr in self.trackers),
            "sensor_errors": self.sensor_errors,
        }

    async def close(self) -> None:
        self.sun.save()
        for sensor in (self.pyranometer, self.anemometer):
            if sensor is not None:
                await sensor.close()
        for tr in self.trackers:
            await self._close_quietly(tr.drive)
