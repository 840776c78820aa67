"""A run's report: ``report/`` next to ``cycles.csv`` and ``summary.json``.

:func:`write_report` is the library call behind ``simulate``, ``replay``, ``run`` (at exit)
and ``heliotrack report DIR``: PNG figures (:mod:`heliotrack.reports.figures`) and one
self-contained ``index.html`` (figures embedded as data URIs, the summary as tables, no
external file, script or font: it opens offline).
"""

from __future__ import annotations

import base64
import html
import io
import json
import logging
import math
from collections.abc import Callable
from pathlib import Path

import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from controller.atomic import atomic_write
from controller.errors import InputError

from ..interrupt import raise_if_interrupted, sigint_noted
from ..output import span_text
from . import figures

log = logging.getLogger(__name__)

__all__ = ["load_run", "write_report"]

#: Text columns of cycles.csv (empty when a run did not write them).
TEXT_COLUMNS = ("mode", "reason", "source", "alarms", "error", "health", "health_reason")

#: (file stem, caption) of each figure, in page order.
CAPTIONS = {
    "sky_dome": "The sun path on a sky dome: the controller's estimates by source, and the true sun.",
    "pointing_error": "Pointing error against time, per tracker.",
    "timeline": "Modes and sun sources on a timeline (weather stows and alarms in red).",
    "setpoints": "Setpoint against actual angle, per tracker and axis.",
    "daily_sun_path": "Noon-time and site errors of the sun-path filter, per day.",
    "sky_classes": "Sky class per day from the pyranometer.",
}


def load_run(folder: Path) -> tuple[pd.DataFrame, dict]:
    """``cycles.csv`` (with a parsed ``time`` column) and ``summary.json`` of a run folder."""
    folder = Path(folder)
    summary_path, cycles_path = folder / "summary.json", folder / "cycles.csv"
    for p in (summary_path, cycles_path):
        if not p.is_file():
            raise InputError(f"{p}: not found (a run folder holds summary.json and cycles.csv)")
    try:
        summary = json.loads(summary_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{summary_path}: not a JSON summary ({exc})") from None
    if not isinstance(summary, dict):
        raise InputError(f"{summary_path}: expected a JSON object")
    try:
        text = {c: str for c in ("reason", "alarms", "error", "health_reason", "status", "health")}
        df = pd.read_csv(cycles_path, dtype=text)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(f"{cycles_path}: not a cycles.csv ({exc})") from None
    missing = {"time_utc", "tracker", "mode", "source"} - set(df.columns)
    if missing:
        raise InputError(f"{cycles_path}: missing column(s) {', '.join(sorted(missing))}")
    df["time"] = pd.to_datetime(df["time_utc"], utc=True, format="ISO8601", errors="coerce")
    df = df[df["time"].notna()].copy()
    if df.empty:
        raise InputError(
            f"{cycles_path}: no cycle with a readable time_utc (a run stopped before its first cycle?)"
        )
    for col in TEXT_COLUMNS:  # a writer of fewer columns (an older run) still gets a report
        df[col] = df[col].fillna("").astype(str) if col in df else ""
    df["tracker"] = df["tracker"].astype(str)
    for col in df.columns:
        if col.endswith(("_deg", "_w_m2", "_ms")):
            df[col] = pd.to_numeric(df[col], errors="coerce")
    return df, summary


def _truth(df: pd.DataFrame, summary: dict) -> pd.DataFrame | None:
    """The true sun at the cycles' times: recorded in cycles.csv, else the ephemeris."""
    plant = df[df["tracker"] == df["tracker"].iloc[0]] if not df.empty else df
    if "true_sun_az_deg" in plant and plant["true_sun_az_deg"].notna().any():
        out = pd.DataFrame({"az": plant["true_sun_az_deg"], "el": plant["true_sun_el_deg"]}).dropna()
        out.attrs["label"] = "true sun"
        return out
    site = summary.get("site") or {}
    if plant.empty or "latitude" not in site:
        return None
    import pvlib

    pos = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex(plant["time"]), site["latitude"], site["longitude"], site.get("altitude", 0.0)
    )
    out = pd.DataFrame({"az": pos["azimuth"].to_numpy(), "el": pos["apparent_elevation"].to_numpy()})
    out.attrs["label"] = "ephemeris (pvlib SPA)"
    return out


def _png(fig: Figure) -> bytes:
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return buf.getvalue()


def build_figures(df: pd.DataFrame, summary: dict) -> dict[str, bytes]:
    """Every figure the run has data for, as PNG bytes by name."""
    period = float(summary.get("control_period_s") or 60.0)
    makers: dict[str, Callable[[], Figure | None]] = {
        "sky_dome": lambda: figures.sky_dome(df, _truth(df, summary)) if not df.empty else None,
        "pointing_error": lambda: figures.pointing_error(df),
        "timeline": lambda: figures.timeline(df, period),
        "setpoints": lambda: figures.setpoints(df),
        "daily_sun_path": lambda: figures.daily_sun_path(summary),
        "sky_classes": lambda: figures.sky_classes(df, summary),
    }
    out = {}
    with sigint_noted():
        for name, make in makers.items():
            fig = make()
            if fig is not None:
                out[name] = _png(fig)
            raise_if_interrupted()
    return out


def write_report(run_dir: Path, out_dir: Path | None = None) -> Path:
    """Write ``report/`` (PNG figures and ``index.html``) for the run in ``run_dir``;
    return the path of ``index.html``.  ``out_dir``: elsewhere than ``run_dir/report``."""
    df, summary = load_run(Path(run_dir))
    out = Path(out_dir) if out_dir is not None else Path(run_dir) / "report"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file named report, a read-only folder
        raise InputError(f"{out}: cannot make the report folder ({exc.strerror or exc})") from None
    try:
        pngs = build_figures(df, summary)
        index = page(summary, pngs, len(df))
    except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
        # the files are a run's by name but not by content (edited, or another program's)
        log.debug("report of %s failed", run_dir, exc_info=True)
        raise InputError(
            f"{Path(run_dir) / 'summary.json'} and cycles.csv: not the outputs of a heliotrack run "
            f"({type(exc).__name__}: {exc})"
        ) from None
    try:
        for name, data in pngs.items():
            atomic_write(out / f"{name}.png", data)
        for stale in out.glob("*.png"):
            if stale.stem in CAPTIONS and stale.stem not in pngs:
                stale.unlink()
        return atomic_write(out / "index.html", index)
    except OSError as exc:  # a read-only report folder, a full disk: the run's files stand
        raise InputError(
            f"{out}: cannot write the report ({exc.strerror or exc}); the run's summary.json and "
            f"cycles.csv are kept: `heliotrack report {run_dir}` writes it again"
        ) from None


# -- the page ------------------------------------------------------------------------------

STYLE = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1000px; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0 1.2em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
figure { margin: 1.5em 0; } img { max-width: 100%; }
figcaption { color: #555; font-size: 0.9em; }
.warn { color: #b00; font-weight: bold; }
"""


def _fmt(v: object, nd: int = 4) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, float):
        return f"{v:.{nd}f}"
    return str(v)


def _table(header: list[str], rows: list[list[object]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _counts(title: str, counts: dict | None) -> str:
    if not counts:
        return ""
    return f"<h3>{html.escape(title)}</h3>" + _table(
        ["", "count"], [[k, v] for k, v in sorted(counts.items())]
    )


def _trackers_table(summary: dict) -> str:
    rows = []
    entries = list((summary.get("trackers") or {}).items()) + [("all", summary)]
    for name, t in entries:
        p = t.get("pointing_error_deg") or {}
        rows.append(
            [
                name,
                p.get("mean"),
                p.get("rms"),
                p.get("p95"),
                p.get("max"),
                p.get("n"),
                t.get("energy_ratio"),
                t.get("poa_global_kwh_m2"),
                t.get("errors", ""),
            ]
        )
    header = [
        "tracker",
        "mean deg",
        "rms deg",
        "p95 deg",
        "max deg",
        "samples",
        "beam ratio",
        "POA kWh/m2",
        "errors",
    ]
    return _table(header, rows)


def _camera_section(summary: dict) -> str:
    parts = [_counts("Camera frames", summary.get("camera_frames"))]
    sp = summary.get("sun_path") or {}
    if "lat_deg" in sp:
        rows = [
            ["latitude", sp["lat_deg"], sp.get("lat_sigma_deg"), sp.get("lat_error_deg")],
            ["longitude", sp["lon_deg"], sp.get("lon_sigma_deg"), sp.get("lon_error_deg")],
        ]
        parts.append("<h3>Learned site</h3>" + _table(["", "deg", "sigma deg", "error deg"], rows))
    return "".join(parts)


def _weather_section(summary: dict) -> str:
    w = summary.get("weather")
    if not w:
        return ""
    rows = [[k, w.get(k)] for k in ("storms", "alarms", "stow_mode_worst_s", "stowed_worst_s") if k in w]
    return "<h3>Weather</h3>" + _table(["", ""], rows)


def page(summary: dict, pngs: dict[str, bytes], n_rows: int) -> str:
    """The self-contained HTML page."""
    command = summary.get("command", "run")
    title = f"heliotrack {command}: {summary.get('start', '')}"
    sky = ", ".join(summary.get("sky") or [])
    lead = (
        f"{span_text(summary)} from {summary.get('start', '?')}"
        + (f" ({sky})" if sky else "")
        + f", {summary.get('cycles', '?')} cycles of {summary.get('control_period_s', '?')} s, "
        f"{n_rows} rows in cycles.csv, {summary.get('wall_s', '?')} s wall"
    )
    notes = []
    if summary.get("interrupted"):
        notes.append('<p class="warn">Interrupted: the figures cover the cycles run so far.</p>')
    for w in summary.get("warnings") or []:
        notes.append(f'<p class="warn">{html.escape(str(w))}</p>')
    figs = "".join(
        f'<figure><img alt="{name}" src="data:image/png;base64,{base64.b64encode(data).decode()}">'
        f"<figcaption>{html.escape(CAPTIONS[name])}</figcaption></figure>"
        for name, data in pngs.items()
    )
    n_trackers = len(summary.get("trackers") or {})
    if n_trackers > figures.MAX_TRACKERS:
        notes.append(f"<p>Figures show the first {figures.MAX_TRACKERS} of {n_trackers} trackers.</p>")
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1><p>{html.escape(lead)}</p>{''.join(notes)}"
        "<h2>Summary</h2><p>Pointing error in degrees; beam ratio: beam on the plane of array "
        "achieved / an ideal tracker.</p>"
        + _trackers_table(summary)
        + _counts("Modes (tracker-cycles)", summary.get("modes"))
        + _counts("Sun sources (tracker-cycles)", summary.get("sources"))
        + _camera_section(summary)
        + _weather_section(summary)
        + f"<h2>Figures</h2>{figs}</body></html>\n"
    )
