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
from dataclasses import asdict, dataclass, field, replace
from datetime import date, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
from tqdm import tqdm

from controller.clock import SimClock
from controller.config import Config, DualAxisTracker, SingleAxisTracker, TrackerConfig
from controller.drives.links import LinkConfig, ModbusRtuLink, ModbusTcpLink
from controller.drives.modbus import shared_client
from controller.drives.registry import open_drive
from controller.errors import ConfigError
from controller.sensors.pyranometer import ModbusPyranometer
from controller.loop import Controller
from controller.sun.camera import CallableFrameSource
from controller.sunpath.ephemeris import wrap180
from hil.drive import DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from hil.pyranometer import Pyranometer
from hil.sky import sky_series
from hil import truth

from .scenario import HilConfig, as_scenario, axis_params
from .sun_sources import build_sun_source


@dataclass
class TruthTally:
    """What the world saw of one tracker: its panel normal at every daylight sample."""

    samples: list[int] = field(default_factory=list)      # indices into the sample grid
    normals: list[np.ndarray] = field(default_factory=list)
    pointing: list[float] = field(default_factory=list)   # counted samples only


def day_start(d: date, longitude: float) -> float:
    """POSIX time of local mean midnight starting day ``d`` at this longitude."""
    midnight_utc = datetime(d.year, d.month, d.day, tzinfo=timezone.utc)
    return (midnight_utc - timedelta(hours=longitude / 15.0)).timestamp()


def _build_world(config: Config, hil: HilConfig, clock: SimClock, stack: ExitStack,
                 ghi_at=None):
    """Firmware per tracker (and the pyranometer), a server per link.

    Returns (firmwares by tracker name, the links as the controller reaches the emulators
    by link name).
    """
    firmwares: dict[str, DriveFirmware] = {}
    endpoints: dict[str, LinkConfig] = {}
    for link in config.links:
        devices = {}
        for tr in config.trackers:
            if tr.link != link.name:
                continue
            axes = [axis_params(hil, soft, stow)
                    for soft, stow in zip(tr.soft_limits, tr.stow_angles)]
            fw = DriveFirmware(axes, clock.now, heartbeat_timeout=config.control.heartbeat_timeout_s)
            firmwares[tr.name] = fw
            devices[tr.device_id] = fw
        pyr = config.pyranometer
        if pyr is not None and pyr.link == link.name and ghi_at is not None:
            devices[pyr.device_id] = Pyranometer(ghi_at, clock.now, seed=hil.seed)
        if not devices:
            continue
        if isinstance(link, ModbusRtuLink):
            pty = stack.enter_context(PtyLink.open())
            stack.enter_context(ModbusServerThread(devices, serial_url=pty.url,
                                                   baudrate=link.baudrate))
            endpoints[link.name] = replace(link, port=pty.path)
        elif isinstance(link, ModbusTcpLink):
            srv = stack.enter_context(ModbusServerThread(devices, tcp=("127.0.0.1", 0)))
            endpoints[link.name] = replace(link, host="127.0.0.1", tcp_port=srv.tcp_port)
        else:
            raise ConfigError(config.file, f"links.{link.name}.kind",
                              "a link kind the simulator emulates (modbus-rtu, modbus-tcp)", link.kind)
    return firmwares, endpoints


def _open_drives(config: Config, endpoints: dict[str, LinkConfig]):
    return {tr.name: open_drive(endpoints[tr.link], tr.device_id) for tr in config.trackers}


def _open_pyranometer(config: Config, endpoints: dict[str, LinkConfig]):
    if config.pyranometer is None:
        return None
    link = endpoints[config.pyranometer.link]
    if isinstance(link, ModbusRtuLink):
        client = shared_client(link.kind, port=link.port, baudrate=link.baudrate,
                               timeout_s=link.timeout_s)
    else:
        assert isinstance(link, ModbusTcpLink)
        client = shared_client(link.kind, host=link.host, port=link.tcp_port,
                               timeout_s=link.timeout_s)
    return ModbusPyranometer(client, config.pyranometer.device_id)


def _panel(tr: TrackerConfig, angles: list[float], sun: np.ndarray) -> tuple[np.ndarray, float]:
    """The panel normal from the drive's true angles, and its pointing error (NaN when the
    sample does not count: backtracking, or the sun outside the rotation limits)."""
    if isinstance(tr, DualAxisTracker):
        n = truth.dual_axis_normal(angles[0], angles[1])
        return n, float(truth.angle_deg(n, sun))
    assert isinstance(tr, SingleAxisTracker)
    n = truth.row_normal(angles[0], tr.axis_azimuth, tr.axis_tilt)
    _, true_rot, bt = truth.row_ideal_rotation(
        sun[None, :], tr.axis_azimuth, tr.axis_tilt, 180.0, tr.gcr, tr.cross_axis_tilt,
        tr.backtrack)
    if bt[0] or abs(true_rot[0]) > tr.max_angle:
        return n, math.nan
    return n, float(truth.row_pointing_error(angles[0], sun, tr.axis_azimuth, tr.axis_tilt))


def _ideal_normals(tr: TrackerConfig, sun: np.ndarray) -> np.ndarray:
    """Normals of an ideal tracker of the same kind (exact angles, exact backtracking)."""
    if isinstance(tr, DualAxisTracker):
        return sun
    assert isinstance(tr, SingleAxisTracker)
    rot, _, _ = truth.row_ideal_rotation(sun, tr.axis_azimuth, tr.axis_tilt, tr.max_angle,
                                         tr.gcr, tr.cross_axis_tilt, tr.backtrack)
    return truth.row_normal(rot, tr.axis_azimuth, tr.axis_tilt)


def _stats(values: list[float]) -> dict:
    if not values:
        return {"mean": None, "p95": None, "max": None, "n": 0}
    a = np.asarray(values)
    return {"mean": round(float(a.mean()), 5), "p95": round(float(np.percentile(a, 95)), 5),
            "max": round(float(a.max()), 5), "n": int(a.size)}


def run_simulation(config: Config, days: int = 1, start: date | datetime | None = None,
                   out_dir: Path | None = None, progress: bool = True,
                   hours: float | None = None) -> dict:
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

    def __init__(self, config: Config, days: int, start: date | datetime | None,
                 progress: bool, hours: float | None = None):
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
        self.n_cycles = max(1, int(round(seconds / self.period)))
        self.sub = self.hil.substeps
        # Truth at every sub-sample of every cycle, in one vectorised call each.
        offsets = (np.arange(self.sub) + 0.5) / self.sub * self.period
        self.t_samples = (self.t0 + np.arange(self.n_cycles)[:, None] * self.period
                          + offsets[None, :]).ravel()
        site = config.site
        self.sun = truth.sun_truth(self.t_samples, site.latitude, site.longitude,
                                   site.altitude, site.temperature_c, self.hil.linke_turbidity)
        self.sun_vecs = self.sun.vectors
        skies = self.hil.skies
        kinds = {d: skies[d % len(skies)] for d in range(days + 1)}
        self.sky = sky_series(self.t_samples, site.latitude, site.longitude, site.altitude,
                              kinds, self.hil.linke_turbidity, seed=self.hil.seed)
        self.clock = SimClock(self.t0)
        self.tally = {tr.name: TruthTally() for tr in config.trackers}
        self.modes: dict[str, int] = {}
        self.sources: dict[str, int] = {}
        self.log_rows: list[dict] = []
        self._sun = self._sensor = None

    def _camera_frames(self):
        """The world's camera, when the controller looks at the sky through one."""
        hs = self.config.hotspot
        if self.config.control.sun_source != "hotspot" or hs is None or hs.frames != "hil":
            return None
        from hil.camera import Site as CameraSite, profile, render_frame

        site = self.config.site
        cam = self.hil.camera
        scn = profile(cam.profile, noise=cam.noise, tilt_deg=cam.tilt_deg).with_(
            site=CameraSite(site.latitude, site.longitude, site.altitude))

        def render(t: float):
            tau = float(np.interp(t, self.t_samples, self.sky.beam_transmittance))
            return render_frame(scn, t, transmittance=tau).image

        return CallableFrameSource(render)

    def ghi_at(self, t: float) -> float:
        """The sky's true GHI at ``t`` (what the emulated pyranometer sees), W/m2."""
        return float(np.interp(t, self.t_samples, self.sky.ghi))

    async def run(self) -> dict:
        wall0 = time.perf_counter()
        with ExitStack() as stack:
            firmwares, endpoints = _build_world(self.config, self.hil, self.clock, stack,
                                                self.ghi_at)
            sun, sensor = build_sun_source(self.config, self._camera_frames())
            self._sun, self._sensor = sun, sensor
            controller = Controller(self.config, _open_drives(self.config, endpoints), sun,
                                    self.clock, sensor=sensor,
                                    pyranometer=_open_pyranometer(self.config, endpoints))
            try:
                await controller.start()
                bar = tqdm(total=self.n_cycles, desc="simulate", unit="cycle",
                           disable=not self.progress, leave=False)
                for i in range(self.n_cycles):
                    self.clock.advance_to(self.t0 + i * self.period)
                    records = await controller.cycle()
                    tracking = {r.tracker for r in records if r.mode == "TRACK" and not r.error}
                    errors = self._sample_truth(i, firmwares, tracking)
                    self._log(records, errors)
                    bar.update(1)
                bar.close()
            finally:
                await controller.close()
        return self._summary(controller.stats(), time.perf_counter() - wall0)

    def _sample_truth(self, i: int, firmwares: dict[str, DriveFirmware],
                      tracking: set[str]) -> dict[str, list[float]]:
        """Advance through the cycle's sub-samples, recording every panel's orientation.

        Pointing error counts only for trackers that were commanded to follow the sun in
        this cycle (not DIFFUSE, STOW or a failed exchange).
        """
        errs: dict[str, list[float]] = {tr.name: [] for tr in self.config.trackers}
        for k in range(i * self.sub, (i + 1) * self.sub):
            self.clock.advance_to(self.t_samples[k])
            if self.sun.elevation[k] <= 0:
                continue
            for tr in self.config.trackers:
                n, e = _panel(tr, firmwares[tr.name].true_angles(), self.sun_vecs[k])
                tally = self.tally[tr.name]
                tally.samples.append(k)
                tally.normals.append(n)
                if not math.isnan(e) and tr.name in tracking:
                    tally.pointing.append(e)
                    errs[tr.name].append(e)
        return errs

    def _log(self, records, errors: dict[str, list[float]]) -> None:
        for rec in records:
            self.sources[rec.source] = self.sources.get(rec.source, 0) + 1
            self.modes[rec.mode] = self.modes.get(rec.mode, 0) + 1
            e = errors[rec.tracker]
            self.log_rows.append(_log_row(rec, float(np.mean(e)) if e else math.nan))

    def _energy(self, tr: TrackerConfig) -> dict:
        """Beam and Perez plane-of-array irradiation of a tracker and of its ideal twin."""
        tally = self.tally[tr.name]
        if not tally.samples:
            return {"energy_ratio": None, "poa_global_kwh_m2": 0.0, "beam": (0.0, 0.0)}
        k = np.asarray(tally.samples)
        normals = np.asarray(tally.normals)
        sun = self.sun_vecs[k]
        dni = self.sky.dni[k]
        beam = float(np.sum(dni * np.clip(np.sum(normals * sun, axis=1), 0, None)))
        ideal = float(np.sum(dni * np.clip(np.sum(_ideal_normals(tr, sun) * sun, axis=1), 0, None)))
        poa = truth.poa_global_perez(normals, self.t_samples[k], self.sun.azimuth[k],
                                     self.sun.elevation[k], self.sky.ghi[k], dni,
                                     self.sky.dhi[k])
        hours = self.period / self.sub / 3600.0
        return {"energy_ratio": round(beam / ideal, 6) if ideal > 0 else None,
                "poa_global_kwh_m2": round(float(np.sum(poa)) * hours / 1000.0, 5),
                "beam": (beam, ideal)}

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

    def _summary(self, modbus: dict, wall: float) -> dict:
        energy = {tr.name: self._energy(tr) for tr in self.config.trackers}
        beam = sum(e["beam"][0] for e in energy.values())
        ideal = sum(e["beam"][1] for e in energy.values())
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
            "pointing_error_deg": _stats(all_err),
            "energy_ratio": round(beam / ideal, 6) if ideal > 0 else None,
            "poa_global_kwh_m2": round(sum(e["poa_global_kwh_m2"] for e in energy.values()), 5),
            "modbus": modbus,
            "modes": self.modes,
            "sources": self.sources,
            **self._sun_path_summary(),
            "trackers": {
                tr.name: {"pointing_error_deg": _stats(self.tally[tr.name].pointing),
                          "energy_ratio": energy[tr.name]["energy_ratio"],
                          "poa_global_kwh_m2": energy[tr.name]["poa_global_kwh_m2"]}
                for tr in self.config.trackers},
            "definitions": {
                "pointing_error_deg": "daylight truth samples (substeps per period) of cycles "
                                      "in TRACK mode, outside backtracking and rotation "
                                      "limits; dual-axis: angle "
                                      "between panel normal and the true sun; single-axis: "
                                      "angle between panel normal and the sun projected on "
                                      "the rotation plane",
                "energy_ratio": "beam irradiation on the plane of array (the sky's DNI) "
                                "achieved / ideal tracker of the same kind (exact truth "
                                "angles, with backtracking)",
                "poa_global_kwh_m2": "global plane-of-array irradiation, pvlib Perez "
                                     "transposition of the sky's GHI/DNI/DHI, albedo 0.2",
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
    def num(v, width=9, fmt=".4f"):
        return f"{v:{width}{fmt}}" if v is not None else f"{'-':>{width}}"

    lines = [f"heliotrack simulate: {summary['days']} day(s) from {summary['start']} "
             f"({', '.join(summary['sky'])}), {summary['cycles']} cycles of "
             f"{summary['control_period_s']:g} s, {summary['wall_s']} s wall",
             f"{'tracker':<16}{'mean':>9}{'p95':>9}{'max':>9}{'beam':>10}{'POA kWh/m2':>12}"]
    rows = [(name, t) for name, t in summary["trackers"].items()] + [("all", summary)]
    for name, t in rows:
        p = t["pointing_error_deg"]
        lines.append(f"{name:<16}{num(p['mean'])}{num(p['p95'])}{num(p['max'])}"
                     f"{num(t['energy_ratio'], 10, '.6f')}{num(t['poa_global_kwh_m2'], 12, '.3f')}")
    m = summary["modbus"]
    modes = ", ".join(f"{k} {v}" for k, v in sorted(summary["modes"].items()))
    lines.append(f"modes (tracker-cycles): {modes}")
    lines.append(f"modbus: {m['transactions']} transactions, {m['errors']} errors, "
                 f"{m['sensor_errors']} sensor errors")
    return "\n".join(lines)
