"""The HIL scenario runner behind ``heliotrack simulate``: the orchestrator.

It builds the world (:mod:`heliotrack.world`: one emulated drive firmware per tracker on
every configured link: Modbus RTU on a pty, Modbus TCP on 127.0.0.1, CANopen on a virtual
CAN bus), the controller (:mod:`heliotrack.devices`: its drive links and pyranometer
through the registry, on the other end of the wire) and a shared simulated clock; then it
steps the clock one control period at a time.  The controller and the world meet only on
the wire.  Between cycles the world samples its own truth (the physical axis angles from
the emulated drives, the sun from pvlib SPA), scored by :mod:`heliotrack.scoring`;
:mod:`heliotrack.output` writes the results.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from contextlib import ExitStack
from dataclasses import asdict
from datetime import UTC, date, datetime, timedelta
from pathlib import Path

import numpy as np
from tqdm import tqdm

from controller.clock import SimClock
from controller.config import Config, TrackerConfig
from controller.loop import Controller, CycleRecord
from controller.store import open_store_or_none
from controller.sun.camera import CallableFrameSource, CameraSunSensor
from controller.sun.source import SunSource
from controller.sunpath.ephemeris import wrap180
from hil import truth
from hil.drive import DriveFirmware
from hil.sky import sky_series

from .devices import open_anemometer, open_drives, open_pyranometer
from .output import log_row, summary_table, write_outputs
from .scenario import as_scenario
from .scoring import DEFINITIONS, TruthGrid, TruthTally, energy, panel, stats
from .sun_sources import build_sun_source
from .weather_truth import WeatherTruth
from .world import build_world

log = logging.getLogger("heliotrack.simulate")

__all__ = ["ScenarioRun", "day_start", "run_simulation", "summary_table", "write_outputs"]


def day_start(d: date, longitude: float) -> float:
    """POSIX time of local mean midnight starting day ``d`` at this longitude."""
    midnight_utc = datetime(d.year, d.month, d.day, tzinfo=UTC)
    return (midnight_utc - timedelta(hours=longitude / 15.0)).timestamp()


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
    ``hours``: run this long instead of ``days`` whole days.
    """
    run = ScenarioRun(config, days, start, progress, hours)
    summary = asyncio.run(run.run())
    if out_dir is not None:
        write_outputs(Path(out_dir), summary, run.log_rows)
    return summary


class ScenarioRun:
    """One simulated run: the world, the controller, the clock and the truth tallies."""

    def __init__(
        self,
        config: Config,
        days: int,
        start: date | datetime | None,
        progress: bool,
        hours: float | None = None,
    ):
        self.config = config = as_scenario(config)
        self.hil = config.hil
        self.days = days if hours is None else max(1, math.ceil(hours / 24))
        self.start = start or self.hil.start
        self.progress = progress
        self.period = config.control.period_s
        if isinstance(self.start, datetime):
            self.t0 = self.start.timestamp()
        else:
            self.t0 = day_start(self.start, config.site.longitude)
        seconds = days * 86400 if hours is None else hours * 3600
        self.n_cycles = max(1, round(seconds / self.period))
        self.sub = self.hil.substeps
        # Truth at every sub-sample of every cycle, in one vectorised call each.
        offsets = (np.arange(self.sub) + 0.5) / self.sub * self.period
        self.t_samples = (
            self.t0 + np.arange(self.n_cycles)[:, None] * self.period + offsets[None, :]
        ).ravel()
        site = config.site
        sun = truth.sun_truth(
            self.t_samples,
            site.latitude,
            site.longitude,
            site.altitude,
            site.temperature_c,
            self.hil.linke_turbidity,
        )
        skies = self.hil.skies
        kinds = {d: skies[d % len(skies)] for d in range(days + 1)}
        sky = sky_series(
            self.t_samples,
            site.latitude,
            site.longitude,
            site.altitude,
            kinds,
            self.hil.linke_turbidity,
            seed=self.hil.seed,
        )
        self.grid = TruthGrid(self.t_samples, sun, sun.vectors, sky)
        self.clock = SimClock(self.t0)
        self.tally = {tr.name: TruthTally() for tr in config.trackers}
        self.row_errors = {tr.name: 0 for tr in config.trackers}
        self.modes: dict[str, int] = {}
        self.sources: dict[str, int] = {}
        self.log_rows: list[dict] = []
        self._sun: SunSource | None = None
        self._sensor: CameraSunSensor | None = None
        wind = config.wind
        self.wind = self.hil.wind.script(self.t0) if wind is not None else None
        self.weather = (
            WeatherTruth(self.wind, wind.gust_stow_m_s)
            if self.wind is not None and wind is not None
            else None
        )

    def _camera_frames(self) -> CallableFrameSource | None:
        """The world's camera, when the controller looks at the sky through one."""
        hs = self.config.hotspot
        if self.config.control.sun_source != "hotspot" or hs is None or hs.frames != "hil":
            return None
        from hil.camera import Site as CameraSite
        from hil.camera import profile, render_frame

        site = self.config.site
        cam = self.hil.camera
        scn = profile(cam.profile, noise=cam.noise, tilt_deg=cam.tilt_deg).with_(
            site=CameraSite(site.latitude, site.longitude, site.altitude)
        )

        def render(t: float) -> np.ndarray:
            tau = float(np.interp(t, self.t_samples, self.grid.sky.beam_transmittance))
            return render_frame(scn, t, transmittance=tau).image

        return CallableFrameSource(render)

    def ghi_at(self, t: float) -> float:
        """The sky's true GHI at ``t`` (what the emulated pyranometer sees), W/m2."""
        return float(np.interp(t, self.t_samples, self.grid.sky.ghi))

    async def run(self) -> dict:
        wall0 = time.perf_counter()
        with ExitStack() as stack:
            world = build_world(self.config, self.hil, self.clock, stack, self.ghi_at, self.wind)
            sun, sensor = build_sun_source(self.config, self._camera_frames(), self.clock.now())
            self._sun, self._sensor = sun, sensor
            store = (
                open_store_or_none(self.config.store.path, log.warning)
                if self.config.store.path is not None
                else None
            )
            if store is not None:
                stack.callback(store.close)
            controller = Controller(
                self.config,
                open_drives(self.config, world.links),
                sun,
                self.clock,
                sensor=sensor,
                pyranometer=open_pyranometer(self.config, world.links),
                anemometer=open_anemometer(self.config, world.links),
                store=store,
            )
            try:
                await controller.start()
                bar = tqdm(
                    total=self.n_cycles, desc="simulate", unit="cycle", disable=not self.progress, leave=False
                )
                for i in range(self.n_cycles):
                    self.clock.advance_to(self.t0 + i * self.period)
                    records = await controller.cycle()
                    tracking = {r.tracker for r in records if r.mode == "TRACK" and not r.error}
                    errors = await self._sample_truth(i, world.firmwares, tracking, controller)
                    self._log(records, errors)
                    bar.update(1)
                bar.close()
            finally:
                await controller.close()
        return self._summary(controller, time.perf_counter() - wall0)

    async def _weather_until(
        self, t: float, controller: Controller, firmwares: dict[str, DriveFirmware]
    ) -> None:
        """Step the clock through the anemometer polls due before ``t``: the controller
        reads the wind between cycles, and the world notes when the drives obey."""
        if self.weather is None:
            return
        while controller.next_weather_poll <= t:
            self.clock.advance_to(max(controller.next_weather_poll, self.clock.monotonic()))
            self.weather.sample(self.clock.monotonic(), firmwares)
            await controller.poll_weather()
            self.weather.sample(self.clock.monotonic(), firmwares)

    async def _sample_truth(
        self, i: int, firmwares: dict[str, DriveFirmware], tracking: set[str], controller: Controller
    ) -> dict[str, list[float]]:
        """Advance through the cycle's sub-samples, recording every panel's orientation.

        Pointing error counts only for trackers that were commanded to follow the sun in
        this cycle (not DIFFUSE, STOW or a failed exchange).
        """
        errs: dict[str, list[float]] = {tr.name: [] for tr in self.config.trackers}
        for k in range(i * self.sub, (i + 1) * self.sub):
            await self._weather_until(self.t_samples[k], controller, firmwares)
            self.clock.advance_to(self.t_samples[k])
            if self.weather is not None:
                self.weather.sample(self.t_samples[k], firmwares)
            if self.grid.sun.elevation[k] <= 0:
                continue
            for tr in self.config.trackers:
                n, e = panel(tr, firmwares[tr.name].true_angles(), self.grid.sun_vecs[k])
                tally = self.tally[tr.name]
                tally.samples.append(k)
                tally.normals.append(n)
                if not math.isnan(e) and tr.name in tracking:
                    tally.pointing.append(e)
                    errs[tr.name].append(e)
        return errs

    def _log(self, records: list[CycleRecord], errors: dict[str, list[float]]) -> None:
        for rec in records:
            self.sources[rec.source] = self.sources.get(rec.source, 0) + 1
            self.modes[rec.mode] = self.modes.get(rec.mode, 0) + 1
            if rec.error:
                self.row_errors[rec.tracker] += 1
            e = errors[rec.tracker]
            self.log_rows.append(log_row(rec, float(np.mean(e)) if e else math.nan))

    def _energy(self, tr: TrackerConfig) -> dict:
        return energy(tr, self.tally[tr.name], self.grid, self.period / self.sub / 3600.0)

    def _sun_path_summary(self) -> dict:
        """The camera's frame outcomes and what the sun-path filter learned (camera runs)."""
        if self._sensor is None:
            return {}
        out = {"camera_frames": dict(self._sensor.outcomes)}
        sp = self._sun.summary() if self._sun is not None else {}
        if sp:
            if "lat_deg" in sp:
                site = self.config.site
                sp["lat_error_deg"] = sp["lat_deg"] - site.latitude
                sp["lon_error_deg"] = float(wrap180(sp["lon_deg"] - site.longitude))
            out["sun_path"] = sp
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

    def _summary(self, controller: Controller, wall: float) -> dict:
        energies = {tr.name: self._energy(tr) for tr in self.config.trackers}
        beam = sum(e["beam"][0] for e in energies.values())
        ideal = sum(e["beam"][1] for e in energies.values())
        all_err = [e for t in self.tally.values() for e in t.pointing]
        return {
            "days": self.days,
            "hours": round(self.n_cycles * self.period / 3600, 4),
            "start": self.start.isoformat(),
            "site": asdict(self.config.site),
            "sky": [self.hil.skies[d % len(self.hil.skies)] for d in range(self.days)],
            "control_period_s": self.period,
            "cycles": self.n_cycles,
            "wall_s": round(wall, 2),
            "pointing_error_deg": stats(all_err),
            "energy_ratio": round(beam / ideal, 6) if ideal > 0 else None,
            "poa_global_kwh_m2": round(sum(e["poa_global_kwh_m2"] for e in energies.values()), 5),
            "modbus": controller.stats(),
            "links": self._link_stats(controller),
            "modes": self.modes,
            "sources": self.sources,
            **self._sun_path_summary(),
            **(
                {
                    "weather": {
                        **self.weather.summary(),
                        "alarms": sum(1 for e in controller.events if e["kind"] == "wind_alarm"),
                    }
                }
                if self.weather is not None
                else {}
            ),
            "trackers": {
                tr.name: {
                    "pointing_error_deg": stats(self.tally[tr.name].pointing),
                    "energy_ratio": energies[tr.name]["energy_ratio"],
                    "poa_global_kwh_m2": energies[tr.name]["poa_global_kwh_m2"],
                    "link": tr.link,
                    "errors": self.row_errors[tr.name],
                }
                for tr in self.config.trackers
            },
            "definitions": {
                **DEFINITIONS,
                "modbus": "transactions, errors and retries of every drive link (Modbus and "
                "CANopen; the key is historical) and pyranometer read errors",
                "errors": "per tracker: control cycles whose exchange with the drive failed",
            },
        }
