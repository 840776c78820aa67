"""The benchmarks' headline figures beside their targets and the papers' numbers.

Each benchmark's JSON (``benchmarks/results/<name>.json``) is read by an extractor that
returns :class:`Headline` rows; ``heliotrack bench`` prints them as a table, writes
``benchmarks/results/summary.md`` and exits non-zero when a row misses its target.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from heliotrack.resources import writable_home

from .summary_fisheye import fisheye as _fisheye
from .summary_fisheye import fisheye_fourth as _fisheye_fourth
from .summary_fisheye import fisheye_selfcal as _fisheye_selfcal
from .summary_fisheye import fisheye_third as _fisheye_third
from .summary_fisheye import fisheye_third_clouds as _fisheye_third_clouds
from .summary_rows import Headline, fmt

RESULTS_DIR = writable_home("benchmarks/results")  # the checkout's, or under the working directory


_f = fmt


def _loop(r: dict) -> list[Headline]:
    t = r["targets"]
    out = []
    for day, d in r["days"].items():
        p = d["pointing_error_deg"]["p95"]
        out.append(
            Headline(
                "loop",
                f"pointing p95, {day}",
                _f(p, 3, " deg"),
                f"<= {t['p95_deg_max']} deg",
                ok=p <= t["p95_deg_max"],
            )
        )
        out.append(
            Headline(
                "loop",
                f"one HIL day wall time, {day}",
                _f(d["wall_s"], 3, " s"),
                f"<= {t['wall_s_max']:g} s",
                ok=d["wall_s"] <= t["wall_s_max"],
            )
        )
        out.append(
            Headline(
                "loop",
                f"energy ratio, {day}",
                _f(d["energy_ratio"], 6),
                f">= {t['energy_ratio_min']}",
                ok=d["energy_ratio"] >= t["energy_ratio_min"],
            )
        )
    return out


def _plant(r: dict) -> list[Headline]:
    t = r["targets"]
    out = []
    for rows, d in r["modbus_tcp"].items():
        out.append(
            Headline(
                "plant",
                f"{rows} Modbus TCP rows: cycle p99",
                _f(d["cycle_p99_s"], 3, " s"),
                f"<= {t['cycle_p99_s_max']:g} s",
                ok=d["cycle_p99_s"] <= t["cycle_p99_s_max"],
            )
        )
    kept = r.get("modbus_tcp_rows_kept_on_1s_cycle")
    if kept is not None:
        out.append(
            Headline(
                "plant",
                "rows kept on a 1-s cycle",
                _f(kept),
                f">= {t['tcp_rows_min']}",
                ok=kept >= t["tcp_rows_min"],
            )
        )
    can = r.get("canopen_virtual_100")
    if can:
        out.append(
            Headline(
                "plant",
                "100 CANopen drives: cycle p99",
                _f(can.get("cycle_p99_s"), 3, " s"),
                f"<= {t['cycle_p99_s_max']:g} s",
                ok=can.get("cycle_p99_s", 1e9) <= t["cycle_p99_s_max"],
            )
        )
    return out


def _sunpath(r: dict) -> list[Headline]:
    out = []
    for site in ("north", "south"):
        for mode in ("kalman_ephemeris", "kalman_free"):
            acc = r[site]["acceptance"][mode]
            for key in (
                "noon_std_s",
                "declination_rmse_deg",
                "max_lat_error_after_day_1_deg",
                "max_lon_error_after_day_1_deg",
                "gap_120min_max_angular_error_deg",
            ):
                a = acc[key]
                out.append(
                    Headline(
                        "sunpath",
                        f"{site} {mode.replace('kalman_', 'Kalman ')}: {key}",
                        _f(a["measured"], 3),
                        f"<= {a['target']:g}",
                        ok=bool(a["pass"]),
                    )
                )
    t3 = r.get("table3", {}).get("summary")
    if t3:
        out.append(
            Headline(
                "sunpath",
                "seed noon std within the paper's range, cloud-free, at sigma",
                ", ".join(f"{s:g}" for s in t3["sigmas_where_noon_holds_clear"]) + " deg",
                "a sigma in 0.25-0.42 deg",
                "29.7 s (22.6-36.8)",
                ok=any(0.25 <= s <= 0.42 for s in t3["sigmas_where_noon_holds_clear"]),
            )
        )
        out.append(
            Headline(
                "sunpath",
                "Kalman ahead of the seed method (same draws)",
                _f(t3["kalman_ahead_clear"] and t3["kalman_ahead_clouds"]),
                "yes",
                ok=t3["kalman_ahead_clear"] and t3["kalman_ahead_clouds"],
            )
        )
    return out


def _skytype(r: dict) -> list[Headline]:
    out = []
    for name, d in r["agreement"].items():
        out.append(
            Headline(
                "skytype",
                f"agreement with sunshine truth, {name}",
                f"{100 * d['agree_default']:.1f} %",
                "beats seed, K_T, CSD",
                f"seed rule {100 * d['agree_seed']:.1f} %",
                ok=bool(d["default_beats_all"]),
            )
        )
    y = r["speed"]["one_year_default_s"]
    out.append(Headline("skytype", "a year of 2-s data", _f(y, 3, " s"), "< 10 s", ok=y < 10))
    return out


def _diffuse(r: dict) -> list[Headline]:
    t, s = r["targets"], r["summary"]
    return [
        Headline(
            "diffuse",
            "overcast days: POA gain, min",
            _f(s["overcast"]["gain_pct_min"], 3, " %"),
            f">= {t['overcast_gain_min_pct']:g} %",
            "vendors: 1-6 %",
            ok=s["overcast"]["gain_pct_min"] >= t["overcast_gain_min_pct"],
        ),
        Headline(
            "diffuse",
            "broken-cloud days: POA loss, worst",
            _f(s["partly-cloudy"]["gain_pct_min"], 3, " %"),
            f">= -{t['partly_cloudy_loss_max_pct']:g} %",
            ok=s["partly-cloudy"]["gain_pct_min"] >= -t["partly_cloudy_loss_max_pct"],
        ),
    ]


def _hotspot(r: dict) -> list[Headline]:
    acc = r["acceptance"]
    kc = r["known_calibration"]
    out = [
        Headline(
            "hotspot",
            "recommended camera, realistic noise: RMS",
            _f(kc["recommended"]["noise"]["default"]["rms_deg"], 3, " deg"),
            "<= 0.1 deg",
            ok=acc.get("recommended_noise_rms_le_0.1"),
        ),
        Headline(
            "hotspot",
            "paper's camera, realistic noise: RMS",
            _f(kc["seed"]["noise"]["default"]["rms_deg"], 3, " deg"),
            "<= 0.3 deg",
            "paper: about 0.3 deg",
            ok=acc.get("seed_noise_rms_le_0.3"),
        ),
        Headline(
            "hotspot",
            "default segmentation per frame",
            _f(r["timing"]["default_median_ms"], 3, " ms"),
            "<= 20 ms",
            f"Algorithm 1: {r['timing']['seed_median_ms']:.0f} ms",
            ok=acc.get("default_median_le_20ms"),
        ),
    ]
    return out


def _persistence(r: dict) -> list[Headline]:
    return [
        Headline("persistence", "kills of a writing process", _f(r["kills"])),
        Headline("persistence", "corruptions", _f(r["corruptions"]), "0", ok=r["corruptions"] == 0),
        Headline(
            "persistence",
            "reopened at their last commit",
            f"{r['at_last_commit']}/{r['kills']}",
            "all",
            ok=r["at_last_commit"] == r["kills"],
        ),
    ]


def _soak(r: dict) -> list[Headline]:
    t = r["targets"]
    acc = r["acceptance"]
    worst = r["recovery_worst_periods"]
    stow = r["wind_stow_worst_s"]
    rss = r["rss_growth_pct"]
    return [
        Headline("soak", "simulated days", _f(r["days"])),
        Headline("soak", "crashes", _f(r["crashes"]), "0", ok=acc["no_crash"]),
        Headline(
            "soak",
            "commands outside the limits",
            _f(r["out_of_limit_commands"]),
            "0",
            ok=acc["no_out_of_limit_command"],
        ),
        Headline(
            "soak",
            "faults survived / injected",
            f"{r['faults_survived']:,}/{r['faults_injected']:,}",
            "all (bar the last minutes')",
            ok=acc["every_fault_survived"],
        ),
        Headline(
            "soak",
            "setpoints lost after recovery",
            _f(r["setpoints_lost_after_recovery"]),
            "0",
            ok=acc["no_setpoint_lost_after_recovery"],
        ),
        Headline(
            "soak",
            "worst recovery (drives, links)",
            _f(worst, 3, " periods"),
            f"<= {t['recovery_worst_periods_max']:g} periods",
            ok=acc["recovery_within_2_periods"],
        ),
        Headline(
            "soak",
            "wind alarm to every row in STOW mode, worst",
            _f(stow, 3, " s"),
            f"<= {t['wind_stow_worst_s_max']:g} s",
            ok=acc["wind_stow_within_60_s"],
        ),
        Headline("soak", "wind alarm to every axis stowed, worst", _f(r["wind_stowed_worst_s"], 3, " s")),
        Headline("soak", "state corruptions", _f(r["state_corruptions"]), "0", ok=acc["no_state_corruption"]),
        Headline(
            "soak",
            "RSS growth, last day vs first",
            _f(rss, 3, " %"),
            f"< {t['rss_growth_pct_max']:g} %",
            ok=acc["rss_growth_under_10_pct"],
        ),
    ]


def _generic(name: str) -> Callable[[dict], list[Headline]]:
    """For a benchmark with an ``acceptance`` (or ``passed``) block and no extractor yet."""

    def rows(r: dict) -> list[Headline]:
        acc = r.get("acceptance")
        if isinstance(acc, dict):
            return [
                Headline(name, k, "", "", ok=bool(v) if isinstance(v, bool) else None)
                for k, v in acc.items()
                if not isinstance(v, dict)
            ]
        if "passed" in r:
            return [Headline(name, "all targets", "", "", ok=bool(r["passed"]))]
        return []

    return rows


EXTRACTORS: dict[str, Callable[[dict], list[Headline]]] = {
    "loop": _loop,
    "plant": _plant,
    "sunpath": _sunpath,
    "skytype": _skytype,
    "diffuse": _diffuse,
    "hotspot": _hotspot,
    "persistence": _persistence,
    "soak": _soak,
    "fisheye": _fisheye,
    "fisheye_third": _fisheye_third,
    "fisheye_third_clouds": _fisheye_third_clouds,
    "fisheye_fourth": _fisheye_fourth,
    "fisheye_selfcal": _fisheye_selfcal,
}


def headlines(name: str, result: dict) -> list[Headline]:
    """Headline rows of one benchmark result (a malformed result gives one failing row)."""
    try:
        return EXTRACTORS.get(name, _generic(name))(result)
    except (KeyError, TypeError, ValueError) as exc:
        return [Headline(name, "result file", f"unreadable ({type(exc).__name__}: {exc})", ok=False)]


def load_results(names: list[str], results_dir: Path = RESULTS_DIR) -> dict[str, dict | None]:
    """Each benchmark's full result, else its quick one (the summary marks it quick), else None."""
    out: dict[str, dict | None] = {}
    for name in names:
        out[name] = None
        for path in (results_dir / f"{name}.json", results_dir / f"{name}-quick.json"):
            try:
                out[name] = json.loads(path.read_text())
                break
            except (OSError, json.JSONDecodeError):
                continue
    return out


def table(rows: list[Headline]) -> str:
    """A plain-text table for the terminal."""
    width = max((len(r.benchmark) + len(r.figure) + 3 for r in rows), default=20)
    lines = []
    for r in rows:
        mark = {True: "ok", False: "MISS", None: ""}[r.ok]
        lines.append(f"{(r.benchmark + ': ' + r.figure):<{width}} {r.value:>16}  {r.target:<22} {mark}")
    return "\n".join(lines)


def markdown(records: dict[str, dict | None]) -> str:
    """``summary.md``: every figure beside its target and the paper's number."""
    out = [
        "# Benchmark summary",
        "",
        "Written by `heliotrack bench`; each figure comes from `benchmarks/results/<name>.json`.",
        "",
        "| benchmark | figure | measured | target | paper | |",
        "|---|---|---|---|---|---|",
    ]
    for name, rec in records.items():
        if rec is None:
            out.append(f"| {name} | (not run) | | | | |")
            continue
        when = f" ({rec.get('finished_utc', '')[:10]}{', quick' if rec.get('quick') else ''})"
        for r in headlines(name, rec["result"]):
            mark = {True: "ok", False: "**miss**", None: ""}[r.ok]
            out.append(f"| {name}{when} | {r.figure} | {r.value} | {r.target} | {r.paper} | {mark} |")
            when = ""
    return "\n".join(out) + "\n"
