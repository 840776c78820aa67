"""The HIL scenario runner behind ``heliotrack simulate`` (and ``replay``): the orchestrator.

It builds the world (:mod:`heliotrack.world`: one emulated drive firmware per tracker on
every configured link: Modbus RTU on a pty, Modbus TCP on 127.0.0.1, CANopen on a virtual
CAN bus), the controller (:mod:`heliotrack.devices`: its drive links and pyranometer
through the registry, on the other end of the wire) and a shared simulated clock; then it
steps the clock one control period at a time.  The controller and the world meet only on
the wire.  Between cycles the world samples its own truth (the physical axis angles from
the emulated drives, the sun from pvlib SPA or a recording), scored by
:mod:`heliotrack.scoring`; :mod:`heliotrack.output` writes the results.

Memory does not grow with the run: the truth is computed one day at a time, the figures
are running sums, and the rows go to ``cycles.csv`` as the run goes.  An interrupted run
(Ctrl-C) stops at the cycle it was in and returns (and writes) a partial summary.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from contextlib import ExitStack
from dataclasses import asdict
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from controller.clock import SimClock
from controller.config import Config, TrackerConfig
from controller.loop import Controller, CycleRecord
from controller.store import open_store_or_none
from controller.sun.camera import CallableFrameSource, CameraSunSensor, FrameSource
from controller.sun.cameras import CameraGroup
from controller.sun.source import SunSource
from controller.sunpath.ephemeris import wrap180
from hil.drive import DriveFirmware

from .devices import open_anemometer, open_drives, open_pyranometer
from .faults import FaultScheduler, FaultyFrameSource
from .interrupt import sleep_unless, stop_on_sigint
from .output import CyclesWriter, check_out_dir, cycle_row, summary_table, write_summary
from .panel_loop import CLOSEDLOOP_DEFINITIONS, closedloop_summary, make_controller
from .renderers import world_renderers
from .scenario import ScenarioConfig, as_scenario
from .scoring import (
    DEFINITIONS,
    ErrorStats,
    TruthGrid,
    TruthSource,
    TruthTally,
    WorldTruth,
    panel,
    truth_grid,
)
from .span import MAX_DAYS, Span, cycles_per_day, day_samples, day_start, simulation_span
from .sun_sources import build_sun_source
from .weather_truth import WeatherTruth
from .world import World, build_world

log = logging.getLogger("heliotrack.simulate")

__all__ = [
    "MAX_DAYS",
    "ScenarioRun",
    "Span",
    "cycles_per_day",
    "day_samples",
    "day_start",
    "run_simulation",
    "simulation_span",
    "summary_table",
    "world_truth",
]


def world_truth(config: Config) -> WorldTruth:
    """The emulated world's truth of a scenario."""
    scenario = as_scenario(config)
    hil = scenario.hil
    return WorldTruth(scenario.site, hil.skies, hil.linke_turbidity, hil.seed)


def run_simulation(
    config: Config,
    days: int = 1,
    start: date | datetime | None = None,
    out_dir: Path | None = None,
    progress: bool = True,
    hours: float | None = None,
) -> dict:
    """Run the HIL scenario; return the summary (and write it under ``out_dir``).

    ``start``: a date (the run begins at local mean midnight) or an aware datetime.
    ``hours``: run this long instead of ``days`` whole days.  An interrupted run returns
    its partial summary with ``"interrupted": true``.
    """
    run = ScenarioRun(config, simulation_span(config, days, start, hours), progress=progress)
    return run.execute(out_dir)


class ScenarioRun:
    """One run: the world, the controller, the clock and the truth tallies.

    ``frames`` replaces the world's rendered camera (a replayed folder or video);
    ``truth`` replaces the emulated world's truth (a recording's); ``speed`` paces the
    simulated clock at that many times the wall clock (None: as fast as it goes);
    ``extra`` is merged into the summary.
    """

    def __init__(
        self,
        config: Config,
        span: Span,
        *,
        progress: bool = True,
        frames: FrameSource | None = None,
        truth: TruthSource | None = None,
        command: str = "simulate",
        speed: float | None = None,
        extra: dict[str, Any] | None = None,
    ):
        self.config: ScenarioConfig = as_scenario(config)
        self.hil = self.config.hil
        self.span = span
        self.t0, self.n_cycles = span.t0, span.n_cycles
        self.period = self.config.control.period_s
        self.days = max(1, math.ceil(self.n_cycles * self.period / 86400 - 1e-9))
        self.progress = progress
        self.command = command
        self.speed = speed
        self.extra = extra or {}
        self.sub = self.hil.substeps
        self.cycles_per_day = cycles_per_day(self.period)
        self.truth: TruthSource = truth if truth is not None else world_truth(self.config)
        self.grid: TruthGrid | None = None
        self.cycle_sun = np.zeros((0, 2))
        self.day = -1
        self._day_open = False
        self.clock = SimClock(self.t0)
        self.tally = {tr.name: TruthTally() for tr in self.config.trackers}
        self.row_errors = {tr.name: 0 for tr in self.config.trackers}
        self.modes: dict[str, int] = {}
        self.sources: dict[str, int] = {}
        self.sun_path_days: list[dict] = []
        self.cycles_done = 0
        self.interrupted = False
        self.writer: CyclesWriter | None = None
        self._frames = frames
        #: Fault injection ([hil.faults]): the scheduler, and the camera it damages.
        self.faults: FaultScheduler | None = None
        self._faulty_frames: FaultyFrameSource | None = None
        self._sun: SunSource | None = None
        self._sensor: CameraSunSensor | CameraGroup | None = None
        wind = self.config.wind
        self.wind = self.hil.wind.script(self.t0) if wind is not None else None
        self.weather = (
            WeatherTruth(self.wind, wind.gust_stow_m_s)
            if self.wind is not None and wind is not None
            else None
        )

    # -- the truth, one day at a time --------------------------------------------------
    def _enter_day(self, day: int) -> None:
        """Compute the truth of the run's day ``day`` (its cycles' sample times)."""
        cycles, samples = day_samples(self.span, self.period, self.sub, day)
        self.grid = truth_grid(self.truth, samples, day)
        sun = self.truth.sun(cycles)
        self.cycle_sun = np.column_stack([sun.azimuth, sun.elevation])
        self.day = day
        self._day_open = True

    def _leave_day(self) -> None:
        """Fold the day's panel normals into the energy sums; note what the filter learned.

        The day's truth stays in place until the next day's replaces it: the emulated
        sensors read it from their server threads, up to the world's closing."""
        if self.grid is None or not self._day_open:
            return
        self._day_open = False
        for tr in self.config.trackers:
            self.tally[tr.name].flush(tr, self.grid, self.period / self.sub / 3600.0)
        learned = self._sun.summary() if self._sensor is not None and self._sun is not None else {}
        if "lat_deg" in learned:
            site = self.config.site
            lon_err = float(wrap180(learned["lon_deg"] - site.longitude))
            mid = self.t0 + (self.day + 0.5) * self.cycles_per_day * self.period
            self.sun_path_days.append(
                {
                    "day": datetime.fromtimestamp(mid, UTC).date().isoformat(),
                    "lat_error_deg": round(learned["lat_deg"] - site.latitude, 5),
                    "lon_error_deg": round(lon_err, 5),
                    # solar noon moves 4 min per degree of longitude, earlier eastwards
                    "noon_error_s": round(-240.0 * lon_err, 2),
                    "accepted": learned.get("accepted", 0),
                }
            )

    def transmittance_at(self, t: float) -> float:
        """The clouds' beam transmittance over the sun at ``t`` (what the camera sees)."""
        assert self.grid is not None
        if self.hil.sun_hidden(t):  # [[hil.sun_gaps]]: clouds hide the sun from the cameras
            return 0.0
        return float(np.interp(t, self.grid.t, self.grid.sky.beam_transmittance))

    def ghi_at(self, t: float) -> float:
        """The sky's true GHI at ``t`` (what the emulated pyranometer sees), W/m2."""
        assert self.grid is not None
        return float(np.interp(t, self.grid.t, self.grid.sky.ghi))

    def _camera_frames(self) -> FrameSource | dict[str, FrameSource] | None:
        """The controller's camera(s): the replayed frames, or the world's renderer of each
        camera whose ``frames = "hil"`` (faults hit the first: the hotspot when fused)."""
        if self._frames is not None:
            return self._frames
        sources: dict[str, FrameSource] = {
            name: CallableFrameSource(render)
            for name, render in world_renderers(self.config, self.transmittance_at).items()
        }
        if sources and self.hil.faults.enabled:
            first = next(iter(sources))
            self._faulty_frames = FaultyFrameSource(sources[first], self.hil.faults.seed)
            sources[first] = self._faulty_frames
        return sources or None

    # -- running -----------------------------------------------------------------------
    def execute(self, out_dir: Path | None = None) -> dict:
        """Run and return the summary; with ``out_dir``, write ``cycles.csv`` as the run
        goes and ``summary.json`` at the end (also when interrupted)."""
        if out_dir is not None:
            out = check_out_dir(Path(out_dir))
            self.writer = CyclesWriter(out / "cycles.csv", self.config.trackers)
        try:
            summary = asyncio.run(self.run())
        finally:
            if self.writer is not None:
                self.writer.close()
        if out_dir is not None and summary["cycles"]:  # none run: the folder keeps what it had
            write_summary(Path(out_dir), summary)
        return summary

    async def run(self) -> dict:
        wall0 = time.perf_counter()
        self._enter_day(0)
        stop = asyncio.Event()
        with ExitStack() as stack:
            stack.enter_context(stop_on_sigint(stop))
            world = build_world(self.config, self.hil, self.clock, stack, self.ghi_at, self.wind)
            sun, sensor = build_sun_source(self.config, self._camera_frames(), self.clock.now())
            self._sun, self._sensor = sun, sensor
            if self.hil.faults.enabled:
                t1 = self.t0 + self.n_cycles * self.period
                self.faults = FaultScheduler(self.config, world, self.clock, self.t0, t1, self._faulty_frames)
            store = (
                open_store_or_none(self.config.store.path, log.warning)
                if self.config.store.path is not None
                else None
            )
            if store is not None:
                stack.callback(store.close)
            controller = make_controller(
                self.config,
                world,
                self.transmittance_at,
                open_drives(self.config, world.links),
                sun,
                self.clock,
                sensor=sensor,
                pyranometer=open_pyranometer(self.config, world.links),
                anemometer=open_anemometer(self.config, world.links),
                store=store,
            )
            bar = tqdm(
                total=self.n_cycles, desc=self.command, unit="cycle", disable=not self.progress, leave=False
            )
            try:
                await controller.start()
                for i in range(self.n_cycles):
                    if stop.is_set():  # Ctrl-C: stop here, keep what was done
                        self.interrupted = True
                        break
                    day, j = divmod(i, self.cycles_per_day)
                    if day != self.day:
                        self._leave_day()
                        self._enter_day(day)
                    self._advance(self.t0 + i * self.period)
                    records = await self._cycle(controller)
                    self._after_cycle(records, controller, world)
                    tracking = {r.tracker for r in records if r.mode == "TRACK" and not r.error}
                    errors = await self._sample_truth(j, world.firmwares, tracking, controller)
                    self._log(records, errors, j, controller)
                    self.cycles_done = i + 1
                    bar.update(1)
                    await self._pace(i, wall0, stop)
            except asyncio.CancelledError:  # cancelled (a second Ctrl-C): keep what was done
                self.interrupted = True
            finally:
                bar.close()
                self._leave_day()
                await controller.close()
        return self._summary(controller, time.perf_counter() - wall0)

    async def _pace(self, i: int, wall0: float, stop: asyncio.Event) -> None:
        """With ``speed``: hold the simulated clock to ``speed`` times the wall clock
        (a Ctrl-C, which sets ``stop``, ends the wait)."""
        if self.speed:
            ahead = (i + 1) * self.period / self.speed - (time.perf_counter() - wall0)
            if ahead > 0:
                await sleep_unless(stop, ahead)

    # -- hooks (fault injection; a soak overrides them to count and carry on) -----------------
    def _advance(self, t: float) -> None:
        """Move the clock to ``t`` and let the fault scheduler act."""
        self.clock.advance_to(t)
        if self.faults is not None:
            self.faults.advance(t)

    async def _cycle(self, controller: Controller) -> list[CycleRecord]:
        return await controller.cycle()

    async def _poll(self, controller: Controller) -> None:
        await controller.poll_weather()

    def _after_cycle(self, records: list[CycleRecord], controller: Controller, world: World) -> None:
        if self.faults is not None:
            self.faults.after_cycle(self.clock.monotonic(), records, controller.safety.order() is not None)

    def _reachable(self, firmwares: dict[str, DriveFirmware]) -> dict[str, DriveFirmware]:
        """The drives no fault cuts off from the controller (the others cannot obey)."""
        if self.faults is None:
            return firmwares
        return {n: fw for n, fw in firmwares.items() if self.faults.ledger.state[n].blocked == 0}

    async def _weather_until(
        self, t: float, controller: Controller, firmwares: dict[str, DriveFirmware]
    ) -> None:
        """Step the clock through the anemometer polls due before ``t``: the controller
        reads the wind between cycles, and the world notes when the drives obey."""
        if self.weather is None:
            return
        while controller.next_weather_poll <= t:
            self._advance(max(controller.next_weather_poll, self.clock.monotonic()))
            self.weather.sample(self.clock.monotonic(), self._reachable(firmwares))
            await self._poll(controller)
            self.weather.sample(self.clock.monotonic(), self._reachable(firmwares))

    async def _sample_truth(
        self, j: int, firmwares: dict[str, DriveFirmware], tracking: set[str], controller: Controller
    ) -> dict[str, list[float]]:
        """Advance through the cycle's sub-samples (cycle ``j`` of the day), recording every
        panel's orientation.

        Pointing error counts only for trackers that were commanded to follow the sun in
        this cycle (not DIFFUSE, STOW or a failed exchange).
        """
        grid = self.grid
        assert grid is not None
        errs: dict[str, list[float]] = {tr.name: [] for tr in self.config.trackers}
        for k in range(j * self.sub, (j + 1) * self.sub):
            t = float(grid.t[k])
            await self._weather_until(t, controller, firmwares)
            self._advance(t)
            if self.weather is not None:
                self.weather.sample(t, self._reachable(firmwares))
            if grid.sun.elevation[k] <= 0:
                continue
            for tr in self.config.trackers:
                fw = firmwares[tr.name]
                n, e = panel(tr, fw.panel_angles(), grid.sun_vecs[k], fw.mount_offsets)
                tally = self.tally[tr.name]
                tally.samples.append(k)
                tally.normals.append(n)
                if not math.isnan(e) and tr.name in tracking:
                    errs[tr.name].append(e)
        for name, values in errs.items():
            self.tally[name].pointing.add(values)
        return errs

    def _log(
        self, records: list[CycleRecord], errors: dict[str, list[float]], j: int, controller: Controller
    ) -> None:
        ghi = None
        samples = controller.diffuse.samples
        if controller.pyranometer is not None and samples and records and samples[-1][0] == records[0].time:
            ghi = samples[-1][1]
        true_sun = (float(self.cycle_sun[j, 0]), float(self.cycle_sun[j, 1]))
        rows = []
        for rec in records:
            self.sources[rec.source] = self.sources.get(rec.source, 0) + 1
            self.modes[rec.mode] = self.modes.get(rec.mode, 0) + 1
            if rec.error:
                self.row_errors[rec.tracker] += 1
            if self.writer is not None:
                e = errors[rec.tracker]
                axes = self.writer.axes[rec.tracker]
                rows.append(cycle_row(rec, axes, float(np.mean(e)) if e else math.nan, true_sun, ghi))
        if self.writer is not None:
            self.writer.write(rows)

    # -- the summary -------------------------------------------------------------------
    def _sun_path_summary(self) -> dict:
        """The camera's frame outcomes and what the sun-path filter learned (camera runs)."""
        if self._sensor is None:
            return {}
        out: dict[str, Any] = {"camera_frames": dict(self._sensor.outcomes)}
        sp = self._sun.summary() if self._sun is not None else {}
        if sp:
            if "lat_deg" in sp:
                site = self.config.site
                sp["lat_error_deg"] = sp["lat_deg"] - site.latitude
                sp["lon_error_deg"] = float(wrap180(sp["lon_deg"] - site.longitude))
            out["sun_path"] = sp
        if self.sun_path_days:
            out["sun_path_days"] = self.sun_path_days
        return out

    @staticmethod
    def _link_stats(controller: Controller) -> dict[str, dict]:
        """Transactions, errors and retries of every link's drives, by link name."""
        out: dict[str, dict] = {}
        for link in controller.config.links:
            drives = [tr.drive for tr in controller.trackers if tr.cfg.link == link.name]
            if drives:
                out[link.name] = {
                    "kind": link.kind,
                    "transactions": sum(d.stats.transactions for d in drives),
                    "errors": sum(d.stats.errors for d in drives),
                    "retries": sum(d.stats.retries for d in drives),
                }
        return out

    def _weather_summary(self, controller: Controller) -> dict:
        if self.weather is None:
            return {}
        alarms = [e for e in controller.events if e["kind"] == "wind_alarm"]
        return {"weather": {**self.weather.summary(), "alarms": len(alarms)}}

    def _sky_labels(self) -> list[str]:
        kind = getattr(self.truth, "sky_kind", None)
        return [kind(d) for d in range(self.days)] if kind is not None else []

    def _energy(self, tr: TrackerConfig) -> dict:
        return self.tally[tr.name].energy()

    def _summary(self, controller: Controller, wall: float) -> dict:
        energies = {tr.name: self._energy(tr) for tr in self.config.trackers}
        beam = sum(t.beam for t in self.tally.values())
        ideal = sum(t.ideal for t in self.tally.values())
        everything = ErrorStats()
        for t in self.tally.values():
            everything = everything.merged(t.pointing)
        cycles = self.cycles_done
        return {
            "command": self.command,
            **({"interrupted": True} if self.interrupted else {}),
            "days": self.days,
            "hours": round(cycles * self.period / 3600, 4),
            "start": self.span.label,
            "site": asdict(self.config.site),
            "sky": self._sky_labels(),
            "control_period_s": self.period,
            "cycles": cycles,
            "wall_s": round(wall, 2),
            "pointing_error_deg": everything.summary(),
            "energy_ratio": round(beam / ideal, 6) if ideal > 0 else None,
            "poa_global_kwh_m2": round(sum(e["poa_global_kwh_m2"] for e in energies.values()), 5),
            "modbus": controller.stats(),
            "links": self._link_stats(controller),
            "modes": self.modes,
            "sources": self.sources,
            **self._sun_path_summary(),
            **({"faults": self.faults.summary()} if self.faults is not None else {}),
            **self._weather_summary(controller),
            **closedloop_summary(controller, self.config),
            "trackers": {
                tr.name: {
                    "type": tr.type,
                    "pointing_error_deg": self.tally[tr.name].pointing.summary(),
                    "energy_ratio": energies[tr.name]["energy_ratio"],
                    "poa_global_kwh_m2": energies[tr.name]["poa_global_kwh_m2"],
                    "link": tr.link,
                    "errors": self.row_errors[tr.name],
                }
                for tr in self.config.trackers
            },
            **self.extra,
            "definitions": {
                **DEFINITIONS,
                "modbus": "transactions, errors and retries of every drive link (Modbus and "
                "CANopen; the key is historical) and pyranometer read errors",
                "errors": "per tracker: control cycles whose exchange with the drive failed",
                **(CLOSEDLOOP_DEFINITIONS if self.config.closedloop is not None else {}),
            },
        }
