"""The controller's side of the SunSpec northbound link: snapshots out, overrides in.

The server thread calls :meth:`Northbound.snapshot` on every Modbus request and hands
accepted operator writes to :meth:`Northbound.on_override`; both only touch a cached
object and a queue, so the control loop never waits on SCADA.  The loop publishes a new
snapshot after each cycle and applies queued overrides before the next.
"""

from __future__ import annotations

import queue
from datetime import UTC, datetime, timedelta

from .config import DualAxisTracker, SingleAxisTracker
from .loop import Controller, CycleRecord
from .sunspec import OverrideCommand, PlantSnapshot, TrackerSnapshot

_ALARM_SETPOINT = 1  # model 601 Alm bit 0: the tracker cannot reach or hold its setpoint


class Northbound:
    """Bridge between a :class:`Controller` and a :class:`controller.sunspec.SunSpecServer`."""

    def __init__(self, controller: Controller, name: str = "heliotrack"):
        self.controller = controller
        self.name = name
        self.overrides: queue.SimpleQueue[OverrideCommand] = queue.SimpleQueue()
        self._snapshot = self._build([])

    # -- server thread ---------------------------------------------------------------
    def snapshot(self) -> PlantSnapshot:
        return self._snapshot

    def on_override(self, cmd: OverrideCommand) -> None:
        self.overrides.put(cmd)

    # -- control loop ----------------------------------------------------------------
    def apply_pending(self) -> int:
        """Hand queued overrides to the controller; returns how many."""
        n = 0
        while True:
            try:
                cmd = self.overrides.get_nowait()
            except queue.Empty:
                return n
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
            mode = rec.mode if rec else "STOW"
            # Alm SetPoint: the tracker cannot reach or hold its setpoint (link or drive)
            alarm = _ALARM_SETPOINT if rec is not None and (rec.error or rec.health != "ok") else 0
            manual = self.controller.overrides.get(tr.index)
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
        local = datetime.fromtimestamp(t, tz=UTC) + timedelta(hours=site.longitude / 15)
        tilts = [tr.cfg.axis_tilt for tr in self.controller.trackers if isinstance(tr.cfg, SingleAxisTracker)]
        return PlantSnapshot(
            self.name,
            plant_type,
            local.replace(tzinfo=None),
            tuple(trackers),
            axis_tilt_deg=max(tilts, default=0.0),
        )
