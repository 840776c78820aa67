"""``heliotrack simulate``: run the HIL scenario and report pointing error and energy."""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, date, datetime
from pathlib import Path

from controller.errors import ConfigError
from heliotrack.resources import bundled_config

DEFAULT_CONFIG = bundled_config("hil-default.toml")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="run the hardware-in-the-loop scenario",
        description="Run the controller against emulated drives on a "
        "simulated clock; write OUT/cycles.csv as the run goes, OUT/summary.json "
        "(partial on Ctrl-C) and OUT/report/ (figures and index.html).",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=DEFAULT_CONFIG,
        help="scenario TOML (default: the embedded config/hil-default.toml)",
    )
    p.add_argument("--days", type=int, default=None, help="days to simulate (default 1, at most 3660)")
    p.add_argument(
        "--start",
        type=str,
        default=None,
        help="first day, YYYY-MM-DD (from local mean midnight), or an ISO time "
        "with offset, e.g. 2024-03-20T06:00+00:00",
    )
    p.add_argument(
        "--hours", type=float, default=None, help="run this many hours instead of --days whole days"
    )
    p.add_argument(
        "--out", type=Path, default=None, help="output folder (default out/simulate; not with --realtime)"
    )
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="hide the progress bar (shown only when stderr is a terminal)",
    )
    p.add_argument("--no-report", action="store_true", help="do not write OUT/report/")
    p.add_argument(
        "--realtime",
        action="store_true",
        help="run on the wall clock (for SCADA clients) instead of simulated days",
    )
    p.add_argument(
        "--duration", type=float, default=None, help="with --realtime: seconds to run (default 60)"
    )
    p.add_argument(
        "--sunspec",
        type=str,
        default=None,
        metavar="HOST:PORT",
        help="with --realtime: serve SunSpec (models 1, 601 and 64601) on this address; "
        "port 0 picks a free one (printed as 'SUNSPEC host:port')",
    )
    # realtime is an operator's session: SCADA's accepted writes (INFO) are seen as they come
    p.set_defaults(func=run, default_log_level=lambda a: "INFO" if a.realtime else "WARNING")


def run(args: argparse.Namespace) -> int:
    from heliotrack.output import check_out_dir
    from heliotrack.runtime import require_hil
    from heliotrack.scenario import load_scenario
    from heliotrack.simulate import ScenarioRun, simulation_span, summary_table
    from heliotrack.span import checked_length

    config = load_scenario(args.config)
    require_hil(config)
    if args.realtime:
        return _realtime(args, config)
    if args.duration is not None:
        raise ConfigError(
            None, "--duration", "--realtime as well (a simulated run spans --days or --hours)", args.duration
        )
    if args.sunspec:
        raise ConfigError(
            None, "--sunspec", "--realtime as well (SCADA polls on the wall clock)", args.sunspec
        )
    days, hours = checked_length(args.days, args.hours)
    start = parse_start(args.start) if args.start else None
    out = check_out_dir(
        args.out if args.out is not None else Path("out/simulate"),
        folders=() if args.no_report else ("report",),
    )
    run = ScenarioRun(
        config,
        simulation_span(config, days, start, hours),
        progress=not args.no_progress and sys.stderr.isatty(),
    )
    from controller.geometry.travel import travel_warnings

    for warning in travel_warnings(config):
        print(f"heliotrack: warning: {warning}", file=sys.stderr)
    summary = run.execute(out)
    print(summary_table(summary))
    return finish(summary, out, report=not args.no_report)


def finish(summary: dict, out: Path, report: bool = True) -> int:
    """After a run: the report, the files written, and 130 when it was interrupted."""
    if not summary["cycles"]:
        print(
            f"no cycle was run{' (interrupted before the first)' if summary.get('interrupted') else ''}: "
            f"nothing written; what {out} held is as it was",
            file=sys.stderr,
        )
        return 130 if summary.get("interrupted") else 1
    written = [out / "summary.json", out / "cycles.csv"]
    if report:
        from heliotrack.reports.run_report import write_report

        written.append(write_report(out))
    print("wrote " + ", ".join(str(p) for p in written))
    if summary.get("interrupted"):
        print("interrupted: the figures above cover the cycles run so far", file=sys.stderr)
        return 130
    return 0


def parse_start(text: str):
    """``--start``: a date (the run starts at local mean midnight) or a time with a zone."""
    from controller.errors import InputError
    from controller.timestamps import YEARS, parse_timestamp

    try:
        day = date.fromisoformat(text)
    except ValueError:
        pass
    else:
        if not YEARS[0] <= day.year <= YEARS[1]:
            raise ConfigError(None, "--start", f"a date in the years {YEARS[0]}-{YEARS[1]}", text)
        return day
    try:
        t = parse_timestamp(text, "--start", require_zone=True)
    except InputError as exc:
        if "is outside" in str(exc):
            raise
        raise ConfigError(None, "--start", "YYYY-MM-DD or an ISO time with a UTC offset", text) from None
    return datetime.fromtimestamp(t, UTC)


def _realtime(args: argparse.Namespace, config) -> int:
    from heliotrack.realtime import run_realtime

    if args.out is not None:  # it prints its counts; the simulated runs write the files
        raise ConfigError(
            None, "--out", "no output folder with --realtime (it writes no files)", str(args.out)
        )
    if args.duration is None:
        args.duration = 60.0
    if not 0 < args.duration <= 7 * 86400:
        raise ConfigError(None, "--duration", "seconds in (0, 604800]", args.duration)
    address = None
    if args.sunspec:
        host, sep, port = args.sunspec.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
            raise ConfigError(None, "--sunspec", "HOST:PORT, e.g. 127.0.0.1:1502", args.sunspec)
        address = (host, int(port))
    counts = run_realtime(config, args.duration, address)
    print(
        f"realtime: {counts['cycles']} cycles, {counts['row_errors']} row errors, "
        f"{counts['overrides']} operator overrides"
    )
    return 0
