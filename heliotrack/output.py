"""What a run writes: ``cycles.csv`` (as the run goes), ``summary.json`` and the table it
prints.  ``simulate``, ``replay`` and ``run`` share it, so one report reads them all.

``cycles.csv`` is tidy for pandas: one row per tracker and cycle, one column per axis
(``target_az_deg``, ``actual_el_deg``, ``target_rot_deg`` for a single-axis row, ...),
the drive status decoded to flag names, the drive's health and the plant's alarms, and
the row's error when its exchange failed.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import os
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any

from controller.atomic import atomic_write
from controller.config import DualAxisTracker, TrackerConfig
from controller.errors import InputError
from controller.records import CycleRecord
from firmware_protocol import Status

#: Axis names in column names, in order (dual-axis: azimuth, elevation; single-axis: rotation).
AXIS_ORDER = ("az", "el", "rot")

#: Columns before the per-axis ones, and after them.
HEAD_COLUMNS = (
    "time_utc",
    "tracker",
    "mode",
    "reason",
    "source",
    "sun_az_deg",
    "sun_el_deg",
    "true_sun_az_deg",
    "true_sun_el_deg",
)
TAIL_COLUMNS = (
    "status",
    "backtracking",
    "pointing_error_deg",
    "ghi_w_m2",
    "health",
    "health_reason",
    "alarms",
    "error",
    "latency_ms",
)


def axis_names(tr: TrackerConfig) -> tuple[str, ...]:
    """Column names of a tracker's axes: ``("az", "el")`` or ``("rot",)``."""
    return ("az", "el") if isinstance(tr, DualAxisTracker) else ("rot",)


def cycle_columns(trackers: Iterable[TrackerConfig]) -> list[str]:
    """The header of ``cycles.csv`` for a plant with these trackers."""
    present = {a for tr in trackers for a in axis_names(tr)}
    axes = [a for a in AXIS_ORDER if a in present]
    per_axis = [
        f"{kind}_{a}{unit}"
        for kind, unit in (("target", "_deg"), ("actual", "_deg"), ("drive_mode", ""))
        for a in axes
    ]
    return [*HEAD_COLUMNS, *per_axis, *TAIL_COLUMNS]


def status_names(status: int) -> str:
    """A drive status word as its flag names, ``AT_TARGET|HOMED`` (empty when none)."""
    return "|".join(f.name for f in Status if f.name and status & f)


def _r(x: float | None, nd: int = 4) -> float | str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else round(x, nd)


def cycle_row(
    rec: CycleRecord,
    axes: Sequence[str],
    pointing_error_deg: float = math.nan,
    true_sun: tuple[float, float] | None = None,
    ghi_w_m2: float | None = None,
) -> dict[str, Any]:
    """One ``cycles.csv`` row: a tracker's cycle (``axes``: its axis names), its mean
    pointing error over the cycle's truth samples (deg), the true sun at the cycle's time
    and the pyranometer's reading, when known."""
    row: dict[str, Any] = {
        "time_utc": datetime.fromtimestamp(rec.time, tz=UTC).isoformat(),
        "tracker": rec.tracker,
        "mode": rec.mode,
        "reason": rec.reason,
        "source": rec.source,
        "sun_az_deg": _r(rec.sun_az_deg),
        "sun_el_deg": _r(rec.sun_el_deg),
        "true_sun_az_deg": _r(true_sun[0]) if true_sun else "",
        "true_sun_el_deg": _r(true_sun[1]) if true_sun else "",
    }
    for i, a in enumerate(axes):
        row[f"target_{a}_deg"] = _r(rec.targets_deg[i], 3) if i < len(rec.targets_deg) else ""
        row[f"actual_{a}_deg"] = _r(rec.actual_deg[i], 3) if i < len(rec.actual_deg) else ""
        row[f"drive_mode_{a}"] = rec.axis_modes[i] if i < len(rec.axis_modes) else ""
    row.update(
        {
            "status": status_names(rec.status),
            "backtracking": int(rec.backtracking),
            "pointing_error_deg": _r(pointing_error_deg),
            "ghi_w_m2": _r(ghi_w_m2, 1),
            "health": rec.health,
            "health_reason": rec.health_reason,
            "alarms": "; ".join(rec.alarms),
            "error": rec.error,
            "latency_ms": round(rec.latency_s * 1000.0, 2),
        }
    )
    return row


class CyclesWriter:
    """``cycles.csv`` written as the run goes: every cycle's rows are on disk (flushed)
    before the next cycle starts, so an interrupted run keeps what it did.

    The file is opened (and an earlier run's truncated) with the first rows only: a run
    that fails or is stopped before its first cycle leaves the folder as it was."""

    def __init__(self, path: Path, trackers: Sequence[TrackerConfig]):
        self.path = Path(path)
        self.axes = {tr.name: axis_names(tr) for tr in trackers}
        self.columns = cycle_columns(trackers)
        self.rows = 0
        self._file: IO[str] | None = None
        self._csv: csv.DictWriter | None = None

    def write(self, rows: Iterable[dict[str, Any]]) -> None:
        rows = list(rows)
        if not rows:
            return
        if self._csv is None:
            self._file = open(self.path, "w", newline="")  # noqa: SIM115 - closed in close()
            self._csv = csv.DictWriter(self._file, fieldnames=self.columns, extrasaction="ignore", restval="")
            self._csv.writeheader()
        assert self._file is not None
        for row in rows:
            self._csv.writerow(row)
            self.rows += 1
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> CyclesWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: What a run writes in its ``--out``: files, and the report's folder.
RUN_FILES = ("cycles.csv", "summary.json")
RUN_FOLDERS = ("report",)


def check_out_dir(
    out: Path, option: str = "--out", files: Sequence[str] = RUN_FILES, folders: Sequence[str] = RUN_FOLDERS
) -> Path:
    """Make ``out`` (and its parents) and prove it writable, before a long run; the
    ``files`` it will write there must not be folders, nor its ``folders`` files (found at
    the end of a run, that had cost the run)."""
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / f".heliotrack-write-test-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"{option}: cannot write to {out}: {exc.strerror or exc}") from None
    for name in files:
        if (out / name).is_dir():
            raise InputError(f"{option}: {out / name} is a folder; a run writes a file there")
    for name in folders:
        if (out / name).exists() and not (out / name).is_dir():
            raise InputError(f"{option}: {out / name} is a file; a run writes a folder there")
    return out


def write_summary(out: Path, summary: dict) -> Path:
    """``out/summary.json``, atomically."""
    return atomic_write(Path(out) / "summary.json", json.dumps(summary, indent=2) + "\n")


def span_text(summary: dict) -> str:
    """The run's span: whole days, or hours when it ran less than a day."""
    hours = summary.get("hours")
    if hours is not None and hours < 24:
        return f"{hours:g} hour(s)"
    return f"{summary.get('days', '?')} day(s)"


def summary_table(summary: dict) -> str:
    """Plain-text table of the headline figures (units in the headers)."""

    def num(v: float | None, width: int = 9, fmt: str = ".4f") -> str:
        return f"{v:{width}{fmt}}" if v is not None else f"{'-':>{width}}"

    command = summary.get("command", "simulate")
    sky = summary.get("sky") or []
    lines = [
        (
            f"heliotrack {command}: {span_text(summary)} from {summary['start']}"
            + (f" ({', '.join(sky)})" if sky else "")
            + f", {summary['cycles']} cycles of {summary['control_period_s']:g} s, {summary['wall_s']} s wall"
            + (" -- INTERRUPTED, partial figures" if summary.get("interrupted") else "")
        ),
        "pointing error (deg), energy: beam on the plane of array achieved / ideal",
        (
            f"{'tracker':<16}{'mean deg':>9}{'rms deg':>9}{'p95 deg':>9}{'max deg':>9}"
            f"{'beam ratio':>11}{'POA kWh/m2':>12}{'errors':>8}"
        ),
    ]
    rows = [(name, t) for name, t in summary["trackers"].items()] + [("all", summary)]
    for name, t in rows:
        p = t["pointing_error_deg"]
        errors = t.get("errors")
        lines.append(
            f"{name:<16}{num(p['mean'])}{num(p.get('rms'))}{num(p['p95'])}{num(p['max'])}"
            f"{num(t['energy_ratio'], 11, '.6f')}{num(t['poa_global_kwh_m2'], 12, '.3f')}"
            f"{errors if errors is not None else '':>8}"
        )
    m = summary["modbus"]
    modes = ", ".join(f"{k} {v}" for k, v in sorted(summary["modes"].items()))
    lines.append(f"modes (tracker-cycles): {modes}")
    sources = ", ".join(f"{k} {v}" for k, v in sorted(summary.get("sources", {}).items()))
    if sources:
        lines.append(f"sun sources (tracker-cycles): {sources}")
    lines += _camera_lines(summary)
    lines += closedloop_lines(summary)
    lines.append(
        f"modbus: {m['transactions']} transactions, {m['errors']} errors, {m['sensor_errors']} sensor errors"
    )
    for name, link in summary.get("links", {}).items():
        lines.append(
            f"link {name} ({link['kind']}): {link['transactions']} transactions, "
            f"{link['errors']} errors, {link['retries']} retries"
        )
    weather = summary.get("weather")
    if weather:
        lines.append(
            f"weather: {weather.get('storms', 0)} storm(s), {weather.get('alarms', 0)} alarm(s), "
            f"worst gust-to-STOW {weather.get('stow_mode_worst_s')} s, "
            f"gust-to-stowed {weather.get('stowed_worst_s')} s"
        )
    return "\n".join(lines)


def _camera_lines(summary: dict) -> list[str]:
    """Camera frames found (of those looked at) and the site the sun-path filter learned."""
    lines = []
    frames = summary.get("camera_frames")
    cameras: dict[str, dict[str, int]] = {}
    for key, n in (frames or {}).items():  # fused cameras: "<camera>: <outcome>"
        cam, _, what = key.rpartition(": ")
        cameras.setdefault(cam, {})[what] = n
    for cam, outcomes in sorted(cameras.items()):
        total = sum(outcomes.values())
        found = outcomes.get("found", 0)
        others = ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()) if k != "found")
        label = f"camera frames ({cam})" if cam else "camera frames"
        lines.append(f"{label}: {found} of {total} found" + (f" ({others})" if others else ""))
    sp = summary.get("sun_path")
    if sp and "lat_deg" in sp:
        lines.append(
            f"learned site: lat {sp['lat_deg']:.4f} deg (sigma {sp['lat_sigma_deg']:.4f}, "
            f"error {sp.get('lat_error_deg', math.nan):+.4f}), lon {sp['lon_deg']:.4f} deg "
            f"(sigma {sp['lon_sigma_deg']:.4f}, error {sp.get('lon_error_deg', math.nan):+.4f}); "
            f"{sp.get('accepted', 0)} observations accepted, {sp.get('rejected', 0)} rejected"
        )
    elif sp:
        lines.append(f"learned site: none yet ({sp.get('accepted', 0)} observations accepted)")
    return lines


def closedloop_lines(summary: dict) -> list[str]:
    """The panel-mounted closed loop's rows: learned offsets (and the world's), setpoints, frames."""
    cl = summary.get("closedloop")
    if not cl:
        return []
    seed = ", the paper's pipeline" if cl.get("algorithm") == "seed" else ""
    lines = [f"closed loop ({cl['mode']}{seed}):"]
    for name, row in cl["rows"].items():
        learned = ", ".join(f"{k} {v:+.3f}" for k, v in row["learned_offset_deg"].items())
        truth = ", ".join(f"{k} {v:+.3f}" for k, v in row.get("mount_offset_deg", {}).items())
        setpoints = ", ".join(f"{k} {v}" for k, v in sorted(row["setpoints"].items()))
        frames = ", ".join(f"{k} {v}" for k, v in sorted(row["frames"].items()))
        lines.append(
            f"  {name}: learned offset (deg) {learned}; mounting offset {truth}; "
            f"setpoints: {setpoints}; frames: {frames}"
        )
    return lines


def warn_names_without_zone(images) -> None:
    """Say once when frames are dated by names without a zone (read as UTC)."""
    from controller.timestamps import names_without_zone, zone_warning

    text = zone_warning(names_without_zone(str(p) for p in images), len(images))
    if text:
        logging.getLogger("heliotrack.estimate").warning(text)
