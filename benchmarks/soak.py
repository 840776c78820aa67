"""Soak: a month of the HIL plant under every fault (issue 13 item 7).

``config/hil-soak.toml``: six trackers on Modbus RTU, Modbus TCP and CANopen, a
pyranometer and an anemometer on the RS-485 line, the hotspot camera (one frame every
30 min, its learned sun-path state saved daily in the store with the history), gusty
days, and every fault type of
``[hil.faults]`` at random rates.  The benchmark adds storms at random moments (about
one every two and a half days, peaks 18-26 m/s, the alarm at any second of a cycle) and
runs ``days`` simulated days (default 30) through :class:`benchmarks.soak_run.SoakRun`.

Acceptance (the issue's): no crash, no command outside the limits, no corrupt state, no
setpoint lost after a recovery, every drive back in service within 2 control periods of
its fault clearing, every row in STOW mode within 60 s of a gust alarm, RSS growth under
10 % from the first day to the last.
"""

from __future__ import annotations

import asyncio
import random
import tempfile
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

from .soak_run import SoakRun, finite

DESCRIPTION = "30 simulated days of a mixed plant under every fault type, storms at random moments"
SCENARIO = Path(__file__).resolve().parents[1] / "config" / "hil-soak.toml"
TARGETS = {
    "crashes": 0,
    "out_of_limit_commands": 0,
    "state_corruptions": 0,
    "setpoints_lost_after_recovery": 0,
    "recovery_worst_periods_max": 2.0,
    "wind_stow_worst_s_max": 60.0,
    "rss_growth_pct_max": 10.0,
}

DEFINITIONS = {
    "recovery_worst_event": "the slowest recovery of a row: the row, the faults it waited "
    "for, when the last of them cleared and when the row was back in service (POSIX s)",
    "out_of_limit_samples": "the first of those targets as the drives noted them: the "
    "drive's time, axis, value, the limits it broke and the drive's own soft limits then",
    "crashes": "unhandled exceptions: raised out of the controller's cycle or wind poll (the "
    "soak catches them and goes on), or a row's cycle ended by an exception type the loop did "
    "not expect (its record reads '<row>: <Type>: ...')",
    "out_of_limit_commands": "targets written to an emulated drive (any transport, any drive "
    "incl. ones replaced by a restart) outside the axis's soft limits of the moment or its "
    "tracker's configured travel, counted by the firmware",
    "setpoints_lost_after_recovery": "cycles, after a fault touching the row had cleared, in "
    "which its drive was reachable (no fault cutting it off active, no wire fault on its "
    "replies in the cycle) but did not receive the cycle's targets (a write per axis, with the "
    "values of the cycle's record), or the row's exchange failed",
    "recovery_worst_periods": "worst, over faults of drives and links, of the control periods "
    "from the clearing of the last fault that touched a row (the cause removed: a jam freed, "
    "a switch released, an emulator back, a bus back) to the row's next cycle in service "
    "(exchange ok, health ok, no latched fault, drive in the commanded mode)",
    "recovery_worst_periods_plant": "the same for faults of the plant's sensors, camera and "
    "wall clock (judged on every row)",
    "wind_alarms": "onsets of the controller's wind alarm, by cause (a storm's gust or mean, or "
    "an anemometer giving no valid reading for silent_timeout_s)",
    "wind_stow_worst_s": "worst, over storms, of the time from the true 3-s gust crossing "
    "gust_stow_m_s (the world's wind) to every reachable row's drive read back in STOW mode "
    "(the world's firmware; a drive cut off by a fault at that moment cannot obey and is left "
    "out)",
    "wind_stowed_worst_s": "the same, to every axis at its stow angle (bounded by the drives' "
    "speed: reported, no target)",
    "state_corruptions": "times the store failed its integrity check, or the sun-path state the "
    "controller saved in it failed to load and validate (controller.sunpath.state."
    "load_from_store), checked after each of the controller's day changes (when it saves)",
    "memory_by_day": "where the memory was at each rss_mb_by_day sample: threads, objects the "
    "garbage collector tracks, glibc's heaps (all arenas) obtained by sbrk and by mmap, "
    "allocated and held free (MB)",
    "rss_growth_pct": "resident set size at the end of the last simulated day against the end "
    "of the first, percent, each measured after a garbage collection and glibc malloc_trim "
    "(memory freed in the threads' allocator arenas is not held)",
}


def random_storms(t0: float, days: int, seed: int) -> tuple:
    """Storms at random moments: each day has one with probability 0.4 (the first day
    always), starting at a random second of it."""
    from heliotrack.scenario import HilStorm

    rng = random.Random(seed)
    out = []
    for d in range(days):
        if d and rng.random() >= 0.4:
            continue
        start = t0 + d * 86400.0 + rng.uniform(0.0, 86400.0 - 3 * 3600.0)
        out.append(
            HilStorm(
                start=datetime.fromtimestamp(round(start, 3), UTC).isoformat(),
                peak_m_s=round(rng.uniform(18.0, 26.0), 2),
                ramp_s=round(rng.uniform(600.0, 2400.0)),
                hold_s=round(rng.uniform(600.0, 5400.0)),
            )
        )
    return tuple(out)


def soak_config(days: int, state_dir: Path, seed: int = 29):
    """The soak scenario with its storms and its store (learned state, history) in
    ``state_dir``."""
    from heliotrack.scenario import load_scenario
    from heliotrack.span import day_start

    cfg = load_scenario(SCENARIO)
    t0 = day_start(cfg.hil.start, cfg.site.longitude)
    wind = replace(cfg.hil.wind, storms=random_storms(t0, days, seed))
    return replace(
        cfg,
        hil=replace(cfg.hil, wind=wind),
        store=replace(cfg.store, path=state_dir / "store.sqlite"),
    )


#: Simulated days of a full run and of a quick one (``--days`` changes either).
DAYS = 30
QUICK_DAYS = 1


def run(quick: bool = False, days: int | None = None) -> dict:
    from heliotrack.allocator import bound_heap
    from heliotrack.span import simulation_span

    bound_heap()  # as `heliotrack run` does: the soak stands for a month of it

    days = days or (QUICK_DAYS if quick else DAYS)
    with tempfile.TemporaryDirectory(prefix="heliotrack-soak-") as tmp:
        cfg = soak_config(days, Path(tmp))
        soak = SoakRun(cfg, simulation_span(cfg, days), progress=False)
        summary = asyncio.run(soak.run())
    return result(soak, summary, days)


def result(soak: SoakRun, summary: dict, days: int) -> dict:
    faults = summary.get("faults", {})
    ledger = soak.faults.ledger if soak.faults is not None else None
    weather = summary.get("weather", {})
    ool, writes = soak.out_of_limit()
    period = summary["control_period_s"]
    eps = weather.get("episodes", [])
    out = {
        "days": days,
        "scenario": str(SCENARIO.relative_to(SCENARIO.parents[1])),
        "cycles": summary["cycles"],
        "simulate_wall_s": summary["wall_s"],
        "crashes": sum(soak.crashes.values()),
        "crashes_by_kind": dict(soak.crashes),
        "crash_samples": soak.crash_samples,
        "out_of_limit_commands": ool,
        "out_of_limit_samples": soak.out_of_limit_samples(),
        "recovery_worst_event": ledger.worst_event if ledger is not None else None,
        "target_writes": writes,
        "faults": {
            k: {"injected": v["injected"], "survived": v["survived"], "open_at_end": v["open_at_end"]}
            for k, v in faults.get("by_type", {}).items()
        },
        "faults_injected": faults.get("injected", 0),
        "faults_survived": faults.get("survived", 0),
        "faults_open_at_end": faults.get("open_at_end", 0),
        "recovery_worst_periods_by_type": {
            k: v["recovery_worst_periods"] for k, v in faults.get("by_type", {}).items()
        },
        "recovery_worst_periods": ledger.worst_periods() if ledger else None,
        "recovery_worst_periods_plant": ledger.worst_periods(plant=True) if ledger else None,
        "setpoints_lost_after_recovery": soak.setpoints_lost,
        "setpoints_checked": soak.setpoints_checked,
        "setpoints_lost_samples": soak.setpoints_lost_samples,
        "wind_alarms": sum(soak.wind_alarms.values()),
        "wind_alarms_by_cause": dict(soak.wind_alarms),
        "storms": weather.get("storms", 0),
        "wind_stow_worst_s": finite(weather.get("stow_mode_worst_s")),
        "wind_stowed_worst_s": finite(weather.get("stowed_worst_s")),
        "storm_alarm_second_of_cycle": [round(e["alarm_utc_s"] % period, 1) for e in eps],
        "storm_episodes": eps,
        "state_corruptions": len(soak.state_corruptions),
        "state_checks": soak.state_checks,
        "state_corruption_samples": soak.state_corruptions[:10],
        "rss_mb_by_day": [round(b / 2**20, 1) for b in soak.rss_by_day],
        "rss_growth_pct": soak.rss_growth_pct(),
        "memory_by_day": soak.memory_by_day,
        "event_loop_errors_handled": dict(soak.loop_errors),
        "thread_errors": dict(soak.thread_errors),
        "links": summary.get("links", {}),
        "modes": summary.get("modes", {}),
        "sources": summary.get("sources", {}),
        "camera_frames": summary.get("camera_frames", {}),
        "energy_ratio": summary.get("energy_ratio"),
        "targets": TARGETS,
        "definitions": {**DEFINITIONS, **faults.get("definitions", {})},
    }
    out["acceptance"] = acceptance(out)
    return out


def acceptance(r: dict) -> dict[str, bool]:
    t = TARGETS
    worst = r["recovery_worst_periods"]
    stow = r["wind_stow_worst_s"]
    rss = r["rss_growth_pct"]
    return {
        "no_crash": r["crashes"] == t["crashes"],
        "no_out_of_limit_command": r["out_of_limit_commands"] == t["out_of_limit_commands"],
        "no_state_corruption": r["state_corruptions"] == t["state_corruptions"],
        "no_setpoint_lost_after_recovery": r["setpoints_lost_after_recovery"]
        == t["setpoints_lost_after_recovery"],
        "every_fault_survived": r["faults_survived"] + r["faults_open_at_end"] == r["faults_injected"],
        "recovery_within_2_periods": worst is not None and worst <= t["recovery_worst_periods_max"],
        "wind_stow_within_60_s": stow is not None and stow <= t["wind_stow_worst_s_max"],
        "rss_growth_under_10_pct": rss is not None and rss < t["rss_growth_pct_max"],
    }
