"""The controller's side of the SunSpec northbound link: snapshots out, overrides in.

The server thread calls :meth:`Northbound.snapshot` on every Modbus request and hands
accepted operator writes to :meth:`Northbound.on_override`; both only touch a cached
object and a queue, so the control loop never waits on SCADA.  The loop publishes a new
snapshot after each cycle and applies queued overrides and stow requests before the next.

The weather (vendor model 64601) comes from the loop's :class:`~controller.safety.SafetyState`:
the stow in force and the snow/hail requests at publication; the anemometer's readings
and a wind stow that started since (the loop polls the anemometer between cycles) at
once, so that SCADA sees each poll's wind and model 601 writes are refused (exception 6)
from the gust on, not from the next cycle on.
"""

from __future__ import annotations

import logging
import queue
from dataclasses import replace
from typing import TypedDict

from .config import DualAxisTracker, SingleAxisTracker
from .loop import Controller, CycleRecord
from .safety import SafetyState
from .sun.source import site_local_time
from .sunspec import OverrideCommand, PlantSnapshot, StowRequest, TrackerSnapshot, WeatherSnapshot
from .sunspec.snapshot import SUNSPEC_SOURCE
from .weather import WindState

log = logging.getLogger("heliotrack.sunspec")

_ALARM_SETPOINT = 1  # model 601 Alm bit 0: the tracker cannot reach or hold its setpoint


def _anemometer_lost(wind: WindState) -> bool:
    # WindMonitor's reason while no valid reading arrives (controller.weather)
    return wind.alarm and wind.reason.startswith("anemometer silent")


class _Readings(TypedDict):
    speed_m_s: float | None
    gust_m_s: float | None
    mean_10min_m_s: float | None


def _readings(safety: SafetyState) -> _Readings:
    """The anemometer's last valid reading, as :class:`WeatherSnapshot` fields."""
    last = safety.monitor.last if safety.monitor is not None else None
    return {
        "speed_m_s": last.speed_m_s if last is not None else None,
        "gust_m_s": last.gust_m_s if last is not None else None,
        "mean_10min_m_s": last.mean_10min_m_s if last is not None else None,
    }


class Northbound:
    """Bridge between a :class:`Controller` and a :class:`controller.sunspec.SunSpecServer`."""

    def __init__(self, controller: Controller, name: str = "heliotrack"):
        self.controller = controller
        self.name = name
        self.overrides: queue.SimpleQueue[OverrideCommand | StowRequest] = queue.SimpleQueue()
        self._snapshot = self._build([])
        self._live: tuple[PlantSnapshot, WindState, PlantSnapshot] | None = None

    # -- server thread ---------------------------------------------------------------
    def snapshot(self) -> PlantSnapshot:
        """The published snapshot with the anemometer's readings polled since and, with a
        wind stow that started since, marked as one (the same object while nothing changes,
        so the server's per-tracker work is skipped; each poll makes a new ``wind``)."""
        safety = self.controller.safety
        snap, wind = self._snapshot, safety.wind  # each read is atomic
        live = self._live
        if live is not None and live[0] is snap and live[1] is wind:
            return live[2]
        weather = replace(snap.weather, **_readings(safety), anemometer_lost=_anemometer_lost(wind))
        if wind.stow and weather.stow != "wind":
            weather = replace(weather, stow="wind", reason=wind.reason)
        out = snap if weather == snap.weather else replace(snap, weather=weather)
        self._live = (snap, wind, out)
        return out

    def on_override(self, cmd: OverrideCommand | StowRequest) -> None:
        self.overrides.put(cmd)

    # -- control loop ----------------------------------------------------------------
    def apply_pending(self) -> int:
        """Hand queued overrides and stow requests to the controller; returns how many."""
        n = 0
        while True:
            try:
                cmd = self.overrides.get_nowait()
            except queue.Empty:
                return n
            if isinstance(cmd, StowRequest):
                self.controller.safety.request(SUNSPEC_SOURCE, cmd.kind)
                log.warning(
                    "SunSpec %s from %s",
                    f"{cmd.kind} stow requested" if cmd.kind else "stow request withdrawn",
                    cmd.peer or "?",
                )
            else:
                self.controller.set_override(cmd.tracker, cmd.ctl, cmd.el_deg, cmd.az_deg)
            n += 1

    def publish(self, records: list[CycleRecord]) -> None:
        self._snapshot = self._build(records)

    def _build(self, records: list[CycleRecord]) -> PlantSnapshot:
        by_name = {r.tracker: r for r in records}
        trackers = []
        for tr in self.controller.trackers:
            cfg, rec = tr.cfg, by_name.get(tr.cfg.name)
            tgt = rec.targets_deg if rec and rec.targets_deg else ()
            pos = rec.actual_deg if rec and rec.actual_deg else ()
            manual = self.controller.overrides.get(tr.index)
            # before the first cycle an override kept over a restart already reads as Manual:
            # SCADA polling at start-up must not see the row released (Ctl = Automatic)
            mode = rec.mode if rec else ("MANUAL" if manual else "STOW")
            # Alm SetPoint: the tracker cannot reach or hold its setpoint (link or drive)
            alarm = _ALARM_SETPOINT if rec is not None and (rec.error or rec.health != "ok") else 0
            if isinstance(cfg, SingleAxisTracker):
                trackers.append(
                    TrackerSnapshot.row(
                        cfg.name,
                        tgt[0] if tgt else None,
                        pos[0] if pos else None,
                        mode,
                        alarm,
                        manual[0] if manual else None,
                        (-cfg.max_angle, cfg.max_angle),
                    )
                )
            elif isinstance(cfg, DualAxisTracker):
                trackers.append(
                    TrackerSnapshot(
                        cfg.name,
                        tgt[1] if tgt else None,
                        tgt[0] % 360 if tgt else None,
                        pos[1] if pos else None,
                        pos[0] % 360 if pos else None,
                        mode,
                        alarm,
                        manual[1] if manual else None,
                        manual[0] % 360 if manual else None,
                        cfg.elevation_limits,
                        None,
                    )
                )
        kinds = {tr.cfg.type for tr in self.controller.trackers}
        # Model 601 has one Typ per controller; a mixed plant reports dual-axis and its
        # rows carry their rotation in the elevation points (azimuth unimplemented).
        plant_type = "dual-axis" if "dual-axis" in kinds else "single-axis"
        site = self.controller.config.site
        t = records[0].time if records else self.controller.clock.now()
        local = site_local_time(site, t)
        tilts = [tr.cfg.axis_tilt for tr in self.controller.trackers if isinstance(tr.cfg, SingleAxisTracker)]
        return PlantSnapshot(
            self.name,
            plant_type,
            local,
            tuple(trackers),
            axis_tilt_deg=max(tilts, default=0.0),
            weather=self._weather(),
        )

    def _weather(self) -> WeatherSnapshot:
        safety = self.controller.safety
        order = safety.order()
        return WeatherSnapshot(
            stow=order.kind if order is not None else "",
            reason=order.reason if order is not None else "",
            **_readings(safety),
            anemometer_lost=_anemometer_lost(safety.wind),
            requests=tuple(safety.requests.items()),
        )
