"""``heliotrack replay SOURCE``: recorded camera frames through the whole controller."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from heliotrack.resources import bundled_config


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "replay",
        help="feed a frame folder or a video through the controller against emulated drives",
        description="Replay camera frames (a folder of images named by their UTC time, e.g. "
        "2026-03-20T10-15-00Z.png, or a video file) through the whole controller: the "
        "configured camera sensor, the sun-path filter, the modes and the setpoints, against "
        "emulated drives on a simulated clock.  The run's start and span come from the frames "
        "unless --start/--hours say otherwise.  Scored against truth.csv beside the frames "
        "when present (heliotrack hil record writes it), else against the ephemeris.  Writes "
        "OUT/cycles.csv, OUT/summary.json and OUT/report/.",
    )
    p.add_argument("source", type=Path, metavar="SOURCE", help="frame folder or video file")
    p.add_argument(
        "--config",
        type=Path,
        default=bundled_config("hil-hotspot.toml"),
        help="scenario TOML with a camera sun source (default: the embedded config/hil-hotspot.toml)",
    )
    p.add_argument(
        "--start",
        type=str,
        default=None,
        help="ISO time with a zone: a video's first frame (default: the time in its name); "
        "for a folder, start the run there instead of at the first frame",
    )
    p.add_argument("--fps", type=float, default=None, help="a video's frame rate (default: the file's)")
    p.add_argument("--hours", type=float, default=None, help="run this long (default: to the last frame)")
    p.add_argument(
        "--speed",
        type=float,
        default=None,
        metavar="X",
        help="pace the simulated clock at X times real time (default: as fast as it goes)",
    )
    p.add_argument("--truth", type=Path, default=None, help="truth CSV (default: SOURCE's truth.csv)")
    p.add_argument("--out", type=Path, default=Path("out/replay"), help="output folder (default out/replay)")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.add_argument("--no-report", action="store_true", help="do not write OUT/report/")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from controller.errors import ConfigError, InputError
    from controller.timestamps import parse_timestamp
    from heliotrack.commands.simulate import finish
    from heliotrack.output import summary_table
    from heliotrack.replay import run_replay
    from heliotrack.runtime import require_hil
    from heliotrack.scenario import load_scenario

    config = load_scenario(args.config)
    require_hil(config)
    start = parse_timestamp(args.start, "--start", require_zone=True) if args.start else None
    if args.fps is not None and not (math.isfinite(args.fps) and 0 < args.fps <= 10_000):
        raise ConfigError(None, "--fps", "frames per second in (0, 10000]", args.fps)
    if args.hours is not None and not 0 < args.hours <= 24 * 366:
        raise ConfigError(None, "--hours", "a number of hours in (0, 8784]", args.hours)
    if args.speed is not None and not (math.isfinite(args.speed) and args.speed > 0):
        raise ConfigError(
            None, "--speed", "a factor > 0 (e.g. 60: a minute of frames per second)", args.speed
        )
    if args.truth is not None and not args.truth.is_file():
        raise InputError(
            f"--truth: {args.truth}: {'a folder, not a file' if args.truth.is_dir() else 'no such file'}"
        )
    from heliotrack.replay import replay_config

    replay_config(config)  # a camera to feed: refused before --out is made
    if not args.source.exists():
        raise InputError(f"{args.source}: no such folder or video file")
    out = args.out  # made by run_replay once the frames are open: a refused input leaves none
    summary = run_replay(
        config,
        args.source,
        start=start,
        fps=args.fps,
        hours=args.hours,
        speed=args.speed,
        truth_file=args.truth,
        out_dir=out,
        report=not args.no_report,
        progress=not args.no_progress and sys.stderr.isatty(),
        warn=lambda text: print(f"heliotrack: warning: {text}", file=sys.stderr),
    )
    print(summary_table(summary))
    return finish(summary, out, report=not args.no_report)
