"""The figures of a run's report, drawn from ``cycles.csv`` (a DataFrame) and the summary.

Each function returns a matplotlib ``Figure`` (object-oriented API, Agg canvas: no pyplot
state, no display needed) or None when the run has nothing to show for it.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.projections.polar import PolarAxes

#: Trackers drawn at most per figure (a plant of 1,000 rows would be unreadable).
MAX_TRACKERS = 8
#: Points drawn at most per series (longer series are thinned evenly).
MAX_POINTS = 6000

MODE_COLOURS = {
    "TRACK": "#2ca02c",
    "DIFFUSE": "#17becf",
    "STOW": "#7f7f7f",
    "STOW (weather)": "#d62728",
    "MANUAL": "#8c564b",
}
SOURCE_COLOURS = {"observed": "#7b3fa0", "predicted": "#ff7f0e", "ephemeris": "#1f77b4", "none": "#bbbbbb"}
HEALTH_COLOURS = {"ok": "#2ca02c", "degraded": "#ff7f0e", "lost": "#d62728"}
WEATHER_WORDS = ("wind", "hail", "snow", "anemometer")


def _thin(frame: pd.DataFrame) -> pd.DataFrame:
    step = max(1, math.ceil(len(frame) / MAX_POINTS))
    return frame.iloc[::step]


def _trackers(df: pd.DataFrame) -> list[str]:
    return list(dict.fromkeys(df["tracker"]))[:MAX_TRACKERS]


def _plant_rows(df: pd.DataFrame) -> pd.DataFrame:
    """One row per cycle (the sun estimate is the plant's): the first tracker's rows."""
    return df[df["tracker"] == df["tracker"].iloc[0]]


def _time_axis(ax, label: str = "time (UTC)") -> None:
    ax.set_xlabel(label)
    ax.grid(True, alpha=0.3)
    for lab in ax.get_xticklabels():
        lab.set_rotation(20)


def sky_dome(df: pd.DataFrame, truth: pd.DataFrame | None) -> Figure | None:
    """The sun path on a sky dome (zenith at the centre, north up, east right): the
    controller's observed, predicted and ephemeris estimates, and the true sun."""
    rows = _plant_rows(df)
    up = rows[rows["sun_el_deg"] > 0]
    if truth is not None:
        truth = truth[truth["el"] > 0]
    if up.empty and (truth is None or truth.empty):
        return None
    fig = Figure(figsize=(7, 7))
    ax = cast(PolarAxes, fig.add_subplot(projection="polar"))
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    for source, colour in SOURCE_COLOURS.items():
        s = _thin(up[up["source"] == source])
        if not s.empty:
            ax.plot(
                np.radians(s["sun_az_deg"]),
                90 - s["sun_el_deg"],
                "o",
                ms=7,
                color=colour,
                alpha=0.5,
                label=source,
            )
    if truth is not None and not truth.empty:
        t = _thin(truth)
        ax.plot(
            np.radians(t["az"]), 90 - t["el"], ".", ms=0.8, color="black", label=t.attrs.get("label", "true")
        )
    ax.set_rlim(0, 90)
    ax.set_rticks([30, 60, 90])
    ax.set_yticklabels(["el 60", "30", "0"])
    ax.set_title("Sun path on the sky dome (elevation rings, azimuth from north)")
    ax.legend(loc="lower left", bbox_to_anchor=(-0.1, -0.1), fontsize=8)
    return fig


def pointing_error(df: pd.DataFrame) -> Figure | None:
    """Pointing error against time, per tracker (mean over each cycle's truth samples)."""
    if "pointing_error_deg" not in df or df["pointing_error_deg"].notna().sum() == 0:
        return None
    fig = Figure(figsize=(10, 4))
    ax = fig.add_subplot()
    for name in _trackers(df):
        s = _thin(df[(df["tracker"] == name) & df["pointing_error_deg"].notna()])
        ax.plot(s["time"], s["pointing_error_deg"], ".", ms=2, label=name)
    ax.set_ylabel("pointing error (deg)")
    ax.set_title("Pointing error per tracker (cycles in TRACK mode, daylight)")
    ax.legend(fontsize=8, markerscale=4)
    _time_axis(ax)
    fig.tight_layout()
    return fig


def _segments(times: np.ndarray, values: list[str], period_s: float) -> dict[str, list[tuple[float, float]]]:
    """Runs of equal values as (start, width) in matplotlib date units, by value."""
    out: dict[str, list[tuple[float, float]]] = {}
    if not len(values):
        return out
    days = period_s / 86400.0
    start = 0
    for i in range(1, len(values) + 1):
        if i == len(values) or values[i] != values[start]:
            end = times[i] if i < len(values) else times[i - 1] + days
            out.setdefault(values[start], []).append((times[start], end - times[start]))
            start = i
    return out


def _mode_label(mode: str, reason: str) -> str:
    if mode == "STOW" and any(w in reason.lower() for w in WEATHER_WORDS):
        return "STOW (weather)"
    return mode


def timeline(df: pd.DataFrame, period_s: float) -> Figure | None:
    """Modes per tracker, the sun source, drive health and the plant's alarms on one
    time axis (weather stows in red)."""
    from matplotlib.dates import date2num
    from matplotlib.patches import Patch

    if df.empty:
        return None
    lanes: list[tuple[str, dict[str, list[tuple[float, float]]], dict[str, str]]] = []
    for name in _trackers(df):
        rows = df[df["tracker"] == name]
        t = date2num(rows["time"])
        labels = [_mode_label(m, r) for m, r in zip(rows["mode"], rows["reason"].fillna(""))]
        lanes.append((f"{name} mode", _segments(t, labels, period_s), MODE_COLOURS))
        health = [h or "ok" for h in rows["health"]] if "health" in rows else []
        if any(h != "ok" for h in health):
            lanes.append((f"{name} health", _segments(t, health, period_s), HEALTH_COLOURS))
    plant = _plant_rows(df)
    t = date2num(plant["time"])
    lanes.append(
        ("sun source", _segments(t, plant["source"].fillna("none").tolist(), period_s), SOURCE_COLOURS)
    )
    alarms = plant["alarms"].fillna("").astype(str).tolist() if "alarms" in plant else []
    if any(alarms):
        flags = ["alarm" if a else "" for a in alarms]
        lanes.append(("alarms", _segments(t, flags, period_s), {"alarm": "#d62728"}))
    fig = Figure(figsize=(10, 1.2 + 0.45 * len(lanes)))
    ax = fig.add_subplot()
    used: dict[str, str] = {}
    for y, (_, segs, colours) in enumerate(reversed(lanes)):
        for value, spans in segs.items():
            if not value:
                continue
            colour = colours.get(value, "#8c564b")
            ax.broken_barh(spans, (y - 0.4, 0.8), facecolors=colour)
            used[value] = colour
    ax.set_yticks(range(len(lanes)))
    ax.set_yticklabels([name for name, _, _ in reversed(lanes)])
    ax.xaxis_date()
    ax.set_title("Modes, sun sources, drive health and alarms")
    ax.legend(
        handles=[Patch(color=c, label=v) for v, c in used.items()],
        fontsize=7,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
    )
    _time_axis(ax)
    fig.tight_layout()
    return fig


def setpoints(df: pd.DataFrame) -> Figure | None:
    """Setpoint against the drive's actual angle, per tracker and axis."""
    panels = []
    for name in _trackers(df):
        rows = df[df["tracker"] == name]
        for axis in ("az", "el", "rot"):
            col = f"target_{axis}_deg"
            if col in rows and rows[col].notna().any():
                panels.append((name, axis, rows))
    if not panels:
        return None
    fig = Figure(figsize=(10, 2.2 * len(panels)))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, axis, rows) in zip(axes, panels):
        s = _thin(rows)
        ax.plot(s["time"], s[f"target_{axis}_deg"], "-", lw=1, label="setpoint")
        ax.plot(s["time"], s[f"actual_{axis}_deg"], "--", lw=1, label="actual")
        ax.set_ylabel(f"{name}\n{axis} (deg)")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    axes[0].set_title("Setpoint against actual angle, per axis")
    _time_axis(axes[-1])
    fig.tight_layout()
    return fig


def daily_sun_path(summary: dict) -> Figure | None:
    """Multi-day runs: the noon-time and site errors of the sun-path filter, per day."""
    days = summary.get("sun_path_days") or []
    if len(days) < 2:
        return None
    d = pd.DataFrame(days)
    x = pd.to_datetime(d["day"])
    fig = Figure(figsize=(10, 5))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(x, d["noon_error_s"], "o-")
    ax1.set_ylabel("noon-time error (s)")
    ax1.axhline(0, color="black", lw=0.5)
    ax1.set_title("What the sun-path filter learned, at the end of each day")
    ax2.plot(x, d["lat_error_deg"], "o-", label="latitude")
    ax2.plot(x, d["lon_error_deg"], "s-", label="longitude")
    ax2.axhline(0, color="black", lw=0.5)
    ax2.set_ylabel("site error (deg)")
    ax2.legend(fontsize=8)
    ax1.grid(True, alpha=0.3)
    _time_axis(ax2, "day")
    fig.tight_layout()
    return fig


def sky_classes(df: pd.DataFrame, summary: dict) -> Figure | None:
    """When a pyranometer is read: the sky class of each day (I clear, II intermediate,
    III overcast) from the controller's own readings, against the scenario's sky."""
    if "ghi_w_m2" not in df:
        return None
    plant = _plant_rows(df)
    plant = plant[plant["ghi_w_m2"].notna()]
    site = summary.get("site") or {}
    if len(plant) < 60 or "longitude" not in site:
        return None
    from controller.sky.classify import analyse_grid
    from controller.sky.grid import build_day_grid
    from controller.sun.source import Site

    t = (plant["time"] - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy()
    try:
        grid = build_day_grid(t, plant["ghi_w_m2"].to_numpy(float), site["longitude"])
        res = analyse_grid(grid, Site(site["latitude"], site["longitude"], site.get("altitude", 0.0)))
    except (ValueError, IndexError):
        return None
    if res.days.empty:
        return None
    classes = {"I": 1, "II": 2, "III": 3}
    dates = [str(d)[:10] for d in res.days["date"]]
    fig = Figure(figsize=(max(7.0, min(14.0, 2 + 0.5 * len(dates))), 3.2))
    ax = fig.add_subplot()
    x = np.arange(len(dates))
    ax.bar(x, [classes.get(c, 0) for c in res.days["class"]], width=0.6, color="#1f77b4")
    sky = summary.get("sky") or []
    start = str(summary.get("start", ""))[:10]
    for xi, d in zip(x, dates):
        try:
            k = (pd.Timestamp(d) - pd.Timestamp(start)).days
        except ValueError:
            continue
        if 0 <= k < len(sky):
            ax.annotate(sky[k], (xi, 0.1), ha="center", fontsize=7, rotation=90, color="white")
    step = max(1, len(dates) // 15)
    ax.set_xticks(x[::step])
    ax.set_xticklabels(dates[::step], rotation=20)
    ax.set_yticks([1, 2, 3])
    ax.set_yticklabels(["I clear", "II intermediate", "III overcast"])
    ax.set_ylim(0, 3.5)
    ax.set_title("Sky class per day, from the pyranometer (bars: the scenario's sky)")
    ax.set_xlabel("day")
    fig.tight_layout()
    return fig
