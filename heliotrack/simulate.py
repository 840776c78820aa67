"""The HIL scenario runner behind ``heliotrack simulate``.

It builds the world (one emulated drive firmware per tracker, served by pymodbus on a pty
per RTU link or on 127.0.0.1 for TCP), the controller (pymodbus clients on the other end),
and a shared simulated clock; then it steps the clock one control period at a time.  The
controller and the world meet only on the wire.  Between cycles the world samples its own
truth: the physical axis angles from the emulated drives and the sun from pvlib SPA.
"""

from __future__ import annotations

import asyncio
import csv
import json
import math
import time
from contextlib import ExitStack
from dataclasses import asdict, dataclass
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
from tqdm import tqdm

from controller.clock import SimClock
from controller.config import Config, TrackerConfig
from controller.drives import open_drive
from controller.loop import Controller
from controller.sun.source import EphemerisSource
from hil.drive import DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil import truth

from .scenario import HilConfig, axis_params, parse_hil


@dataclass
class TruthSamples:
    """Per-tracker truth accumulated over the run."""

    pointing: list[float]
    beam_achieved: float = 0.0
    beam_ideal: float = 0.0
    samples: int = 0


def day_start(d: date, longitude: float) -> float:
    """POSIX time of local mean midnight starting day ``d`` at this longitude."""
    midnight_utc = datetime(d.year, d.month, d.day, tzinfo=timezone.utc)
    return (midnight_utc - timedelta(hours=longitude / 15.0)).timestamp()


def _build_world(config: Config, hil: HilConfig, clock: SimClock, stack: ExitStack):
    """Firmware per tracker, a server per link; returns (firmwares, endpoints per link)."""
    firmwares: dict[str, DriveFirmware] = {}
    endpoints: dict[str, dict] = {}
    for link in config.links.values():
        devices = {}
        for tr in config.trackers:
            if tr.link != link.name:
                continue
            axes = [axis_params(hil, soft, stow) for soft, stow in zip(tr.soft_limits, tr.stow)]
            fw = DriveFirmware(axes, clock.now, heartbeat_timeout=config.control.heartbeat_timeout_s)
            firmwares[tr.name] = fw
            devices[tr.device_id] = fw
        if not devices:
            continue
        if link.kind == "modbus-rtu":
            pty = stack.enter_context(PtyLink.open())
            stack.enter_context(ModbusServerThread(devices, serial_url=pty.url,
                                                   baudrate=link.baudrate))
            endpoints[link.name] = dict(port=pty.path, baudrate=link.baudrate)
        elif link.kind == "modbus-tcp":
            srv = stack.enter_context(ModbusServerThread(devices, tcp=("127.0.0.1", 0)))
            endpoints[link.name] = dict(host="127.0.0.1", port=srv.tcp_port)
        else:
            raise NotImplementedError(f"link kind {link.kind!r} is not emulated yet")
    return firmwares, endpoints


def _open_drives(config: Config, endpoints: dict[str, dict], stack: ExitStack):
    drives = {}
    for tr in config.trackers:
        link = config.links[tr.link]
        ep = endpoints[link.name]
        drives[tr.name] = open_drive(link.kind, device_id=tr.device_id,
                                     timeout_s=link.timeout_s, retries=link.retries, **ep)
    return drives


def _truth_step(tr: TrackerConfig, angles: list[float], sun: np.ndarray, dni: float,
                acc: TruthSamples) -> float:
    """Accumulate one truth sample; return the pointing error (NaN when not counted)."""
    if tr.type == "dual-axis":
        n = truth.dual_axis_normal(angles[0], angles[1])
        err = float(truth.angle_deg(n, sun))
        achieved = dni * max(0.0, float(n @ sun))
        ideal = dni
        counted = True
    else:
        rot_ideal, _, bt = truth.row_ideal_rotation(
            sun[None, :], tr.axis_azimuth, tr.axis_tilt, tr.max_angle, tr.gcr,
            tr.cross_axis_tilt, tr.backtrack)
        n = truth.row_normal(angles[0], tr.axis_azimuth, tr.axis_tilt)
        n_ideal = truth.row_normal(rot_ideal[0], tr.axis_azimuth, tr.axis_tilt)
        achieved = dni * max(0.0, float(n @ sun))
        ideal = dni * max(0.0, float(n_ideal @ sun))
        _, true_unclipped, _ = truth.row_ideal_rotation(
            sun[None, :], tr.axis_azimuth, tr.axis_tilt, 180.0, tr.gcr, backtrack=False)
        counted = not bt[0] and abs(true_unclipped[0]) <= tr.max_angle
        err = float(truth.row_pointing_error(angles[0], sun, tr.axis_azimuth, tr.axis_tilt))
    acc.beam_achieved += achieved
    acc.beam_ideal += ideal
    acc.samples += 1
    if counted:
        acc.pointing.append(err)
        return err
    return math.nan


def _stats(values: list[float]) -> dict:
    if not values:
        return {"mean": None, "p95": None, "max": None, "n": 0}
    a = np.asarray(values)
    return {"mean": round(float(a.mean()), 5), "p95": round(float(np.percentile(a, 95)), 5),
            "max": round(float(a.max()), 5), "n": int(a.size)}


def run_simulation(config: Config, days: int = 1, start: date | None = None,
                   out_dir: Path | None = None, progress: bool = True) -> dict:
    """Run the HIL scenario; return the summary (and write it under ``out_dir``)."""
    run = ScenarioRun(config, days, start, progress)
    summary = asyncio.run(run.run())
    if out_dir is not None:
        write_outputs(Path(out_dir), summary, run.log_rows)
    return summary


class ScenarioRun:
    """One simulated run: the world, the controller, the clock and the truth tallies."""

    def __init__(self, config: Config, days: int, start: date | None, progress: bool):
        self.config = config
        self.hil = parse_hil(config)
        self.days = days
        self.start = start or self.hil.start
        self.progress = progress
        self.period = config.control.period_s
        self.t0 = day_start(self.start, config.site.longitude)
        self.n_cycles = int(round(days * 86400 / self.period))
        self.sub = self.hil.substeps
        # Truth sun at every sub-sample of every cycle, in one vectorised SPA call.
        offsets = (np.arange(self.sub) + 0.5) / self.sub * self.period
        self.t_samples = (self.t0 + np.arange(self.n_cycles)[:, None] * self.period
                          + offsets[None, :]).ravel()
        self.sun = truth.sun_truth(self.t_samples, config.site.latitude, config.site.longitude,
                                   config.site.altitude, config.site.temperature_c,
                                   self.hil.linke_turbidity)
        self.sun_vecs = self.sun.vectors
        self.clock = SimClock(self.t0)
        self.acc = {tr.name: TruthSamples([]) for tr in config.trackers}
        self.sources: dict[str, int] = {}
        self.log_rows: list[dict] = []

    async def run(self) -> dict:
        wall0 = time.perf_counter()
        with ExitStack() as stack:
            firmwares, endpoints = _build_world(self.config, self.hil, self.clock, stack)
            drives = _open_drives(self.config, endpoints, stack)
            controller = Controller(self.config, drives, EphemerisSource(self.config.site),
                                    self.clock)
            try:
                await controller.start()
                bar = tqdm(total=self.n_cycles, desc="simulate", unit="cycle",
                           disable=not self.progress, leave=False)
                for i in range(self.n_cycles):
                    self.clock.advance_to(self.t0 + i * self.period)
                    records = await controller.cycle()
                    errors = self._sample_truth(i, firmwares)
                    self._log(records, errors)
                    bar.update(1)
                bar.close()
            finally:
                await controller.close()
        return self._summary(controller.stats(), time.perf_counter() - wall0)

    def _sample_truth(self, i: int, firmwares: dict[str, DriveFirmware]) -> dict[str, list[float]]:
        """Advance through the cycle's sub-samples, scoring every tracker against the sun."""
        errs: dict[str, list[float]] = {tr.name: [] for tr in self.config.trackers}
        for k in range(i * self.sub, (i + 1) * self.sub):
            self.clock.advance_to(self.t_samples[k])
            if self.sun.elevation[k] <= 0:
                continue
            for tr in self.config.trackers:
                e = _truth_step(tr, firmwares[tr.name].true_angles(), self.sun_vecs[k],
                                float(self.sun.dni[k]), self.acc[tr.name])
                if not math.isnan(e):
                    errs[tr.name].append(e)
        return errs

    def _log(self, records, errors: dict[str, list[float]]) -> None:
        for rec in records:
            self.sources[rec.source] = self.sources.get(rec.source, 0) + 1
            e = errors[rec.tracker]
            self.log_rows.append(_log_row(rec, float(np.mean(e)) if e else math.nan))

    def _summary(self, modbus: dict, wall: float) -> dict:
        acc = self.acc
        all_err = [e for a in acc.values() for e in a.pointing]
        achieved = sum(a.beam_achieved for a in acc.values())
        ideal = sum(a.beam_ideal for a in acc.values())
        return {
            "days": self.days,
            "start": self.start.isoformat(),
            "site": asdict(self.config.site),
            "control_period_s": self.period,
            "cycles": self.n_cycles,
            "wall_s": round(wall, 2),
            "pointing_error_deg": _stats(all_err),
            "energy_ratio": round(achieved / ideal, 6) if ideal > 0 else None,
            "modbus": modbus,
            "sources": self.sources,
            "trackers": {
                name: {"pointing_error_deg": _stats(a.pointing),
                       "energy_ratio": round(a.beam_achieved / a.beam_ideal, 6) if a.beam_ideal else None}
                for name, a in acc.items()},
            "definitions": {
                "pointing_error_deg": "daylight truth samples (substeps per period), outside "
                                      "backtracking and rotation limits; dual-axis: angle "
                                      "between panel normal and the true sun; single-axis: "
                                      "angle between panel normal and the sun projected on "
                                      "the rotation plane",
                "energy_ratio": "sum of clear-sky beam irradiance on the plane of array "
                                "achieved / ideal tracker (exact truth angles, with "
                                "backtracking)",
            },
        }


def _log_row(rec, interval_error: float) -> dict:
    return {
        "time_utc": datetime.fromtimestamp(rec.time, tz=timezone.utc).isoformat(),
        "tracker": rec.tracker, "mode": rec.mode, "reason": rec.reason, "source": rec.source,
        "sun_az_deg": _r(rec.sun_az_deg), "sun_el_deg": _r(rec.sun_el_deg),
        "targets_deg": " ".join(f"{x:.3f}" for x in rec.targets_deg),
        "actual_deg": " ".join(f"{x:.3f}" for x in rec.actual_deg),
        "status": rec.status, "backtracking": int(rec.backtracking),
        "pointing_error_deg": _r(interval_error), "error": rec.error,
    }


def _r(x: float, nd: int = 4):
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else round(x, nd)


def write_outputs(out: Path, summary: dict, rows: list[dict]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if rows:
        with open(out / "cycles.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def summary_table(summary: dict) -> str:
    """Plain-text table of the headline figures."""
    lines = [f"heliotrack simulate: {summary['days']} day(s) from {summary['start']}, "
             f"{summary['cycles']} cycles of {summary['control_period_s']:g} s, "
             f"{summary['wall_s']} s wall",
             f"{'tracker':<16}{'mean':>9}{'p95':>9}{'max':>9}{'energy':>10}"]
    for name, t in summary["trackers"].items():
        p = t["pointing_error_deg"]
        fmt = lambda v: f"{v:9.4f}" if v is not None else f"{'-':>9}"
        lines.append(f"{name:<16}{fmt(p['mean'])}{fmt(p['p95'])}{fmt(p['max'])}"
                     f"{t['energy_ratio'] if t['energy_ratio'] is not None else '-':>10}")
    p = summary["pointing_error_deg"]
    lines.append(f"{'all':<16}{p['mean'] or 0:9.4f}{p['p95'] or 0:9.4f}{p['max'] or 0:9.4f}"
                 f"{summary['energy_ratio']:>10}")
    m = summary["modbus"]
    lines.append(f"modbus: {m['transactions']} transactions, {m['errors']} errors")
    return "\n".join(lines)
