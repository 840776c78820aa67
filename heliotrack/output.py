"""What ``heliotrack simulate`` writes: ``summary.json``, ``cycles.csv`` and the table it
prints."""

from __future__ import annotations

import csv
import json
import math
from datetime import UTC, datetime
from pathlib import Path

from controller.loop import CycleRecord


def log_row(rec: CycleRecord, interval_error: float) -> dict:
    """One ``cycles.csv`` row: a tracker's cycle and its mean pointing error (deg) over the
    cycle's truth samples."""
    return {
        "time_utc": datetime.fromtimestamp(rec.time, tz=UTC).isoformat(),
        "tracker": rec.tracker,
        "mode": rec.mode,
        "reason": rec.reason,
        "source": rec.source,
        "sun_az_deg": _r(rec.sun_az_deg),
        "sun_el_deg": _r(rec.sun_el_deg),
        "targets_deg": " ".join(f"{x:.3f}" for x in rec.targets_deg),
        "actual_deg": " ".join(f"{x:.3f}" for x in rec.actual_deg),
        "status": rec.status,
        "backtracking": int(rec.backtracking),
        "pointing_error_deg": _r(interval_error),
        "error": rec.error,
    }


def _r(x: float | None, nd: int = 4) -> float | str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else round(x, nd)


def write_outputs(out: Path, summary: dict, rows: list[dict]) -> None:
    """``out/summary.json`` and (when there are rows) ``out/cycles.csv``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    if rows:
        with open(out / "cycles.csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


def summary_table(summary: dict) -> str:
    """Plain-text table of the headline figures."""

    def num(v: float | None, width: int = 9, fmt: str = ".4f") -> str:
        return f"{v:{width}{fmt}}" if v is not None else f"{'-':>{width}}"

    lines = [
        (
            f"heliotrack simulate: {summary['days']} day(s) from {summary['start']} "
            f"({', '.join(summary['sky'])}), {summary['cycles']} cycles of "
            f"{summary['control_period_s']:g} s, {summary['wall_s']} s wall"
        ),
        (f"{'tracker':<16}{'mean':>9}{'p95':>9}{'max':>9}{'beam':>10}{'POA kWh/m2':>12}{'errors':>8}"),
    ]
    rows = [(name, t) for name, t in summary["trackers"].items()] + [("all", summary)]
    for name, t in rows:
        p = t["pointing_error_deg"]
        errors = t.get("errors")
        lines.append(
            f"{name:<16}{num(p['mean'])}{num(p['p95'])}{num(p['max'])}"
            f"{num(t['energy_ratio'], 10, '.6f')}{num(t['poa_global_kwh_m2'], 12, '.3f')}"
            f"{errors if errors is not None else '':>8}"
        )
    m = summary["modbus"]
    modes = ", ".join(f"{k} {v}" for k, v in sorted(summary["modes"].items()))
    lines.append(f"modes (tracker-cycles): {modes}")
    lines.append(
        f"modbus: {m['transactions']} transactions, {m['errors']} errors, {m['sensor_errors']} sensor errors"
    )
    for name, link in summary.get("links", {}).items():
        lines.append(
            f"link {name} ({link['kind']}): {link['transactions']} transactions, "
            f"{link['errors']} errors, {link['retries']} retries"
        )
    return "\n".join(lines)
