"""``heliotrack hil record``: write the configured camera's rendered frames and the truth.

The frames are the ones ``simulate`` feeds the controller (same renderer, same clouds,
same times), named by their UTC time in the canonical file-name form
(``2024-03-20T05-12-00.736Z.png``), with ``truth.csv`` beside them: per frame the true sun
(azimuth, elevation), whether it is visible (up and not behind a cloud) and the sky's
irradiance.  ``heliotrack replay`` plays them back through the controller.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from heliotrack.resources import bundled_config


def add_record_parser(hil_subparsers: argparse._SubParsersAction) -> None:
    """Add ``record`` to the ``heliotrack hil`` subcommands."""
    if "record" in hil_subparsers.choices:
        return
    r = hil_subparsers.add_parser(
        "record",
        help="write the configured camera's rendered frames and truth.csv",
        description="Render the frames the configured camera sensor sees in the HIL scenario "
        "(the frames simulate feeds the controller), named by their UTC time, and truth.csv "
        "(time, true sun azimuth and elevation, sun visible or not, the sky's irradiance). "
        "Frames with the sun more than 8 deg below the horizon are skipped unless --night.",
    )
    r.add_argument(
        "--config",
        type=Path,
        default=bundled_config("hil-hotspot.toml"),
        help="scenario TOML with a camera sun source (default: the embedded config/hil-hotspot.toml)",
    )
    r.add_argument("--days", type=int, default=None, help="days to record (default 1)")
    r.add_argument(
        "--start",
        type=str,
        default=None,
        help="first day, YYYY-MM-DD (from local mean midnight), or an ISO time with a zone "
        "(default: the scenario's [hil] start)",
    )
    r.add_argument("--hours", type=float, default=None, help="record this many hours instead of --days")
    r.add_argument(
        "--every",
        type=float,
        default=None,
        metavar="S",
        help="seconds between frames (default: the control period, which replays exactly)",
    )
    r.add_argument("--night", action="store_true", help="also write the frames of the night")
    r.add_argument(
        "--format",
        choices=("png", "jpg"),
        default="png",
        help="png (lossless, default) or jpg (quality 95, about 5x smaller)",
    )
    r.add_argument("--out", type=Path, required=True, help="output folder (new or empty)")
    r.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    r.set_defaults(func=run_record)


#: The most frames one recording writes (a year at one a minute is 525 600).
MAX_FRAMES = 1_000_000


def register(sub: argparse._SubParsersAction) -> None:
    """Until ``heliotrack/commands/hil.py`` calls :func:`add_record_parser` itself: find the
    ``hil`` parser's subcommands and add ``record`` there."""
    hil = sub.choices.get("hil")
    if hil is None:
        return
    for action in hil._actions:
        if isinstance(action, argparse._SubParsersAction):
            add_record_parser(action)


def run_record(args: argparse.Namespace) -> int:
    from controller.errors import ConfigError
    from heliotrack.commands.simulate import parse_start
    from heliotrack.output import check_out_dir
    from heliotrack.recording import record_frames
    from heliotrack.scenario import load_scenario
    from heliotrack.simulate import simulation_span
    from heliotrack.span import checked_length

    config = load_scenario(args.config)
    days, hours = checked_length(args.days, args.hours)
    if args.every is not None and not (math.isfinite(args.every) and 0.01 <= args.every <= 86400):
        raise ConfigError(None, "--every", "seconds in [0.01, 86400]", args.every)
    start = parse_start(args.start) if args.start else None
    span = simulation_span(config, days, start, hours)
    every = args.every or config.control.period_s
    if span.n_cycles * config.control.period_s / every > MAX_FRAMES:  # the times alone took GiB
        raise ConfigError(
            None,
            "--every",
            f"at most {MAX_FRAMES:,} frames over the span ({span.n_cycles * config.control.period_s / 3600:g} h)",
            every,
        )
    out = check_out_dir(args.out, files=("truth.csv",), folders=())
    result = record_frames(
        config,
        span,
        out,
        every_s=args.every,
        night=args.night,
        fmt=args.format,
        progress=not args.no_progress and sys.stderr.isatty(),
    )
    if result.frames:
        print(
            f"wrote {result.frames} frames ({result.first} to {result.last}, every {result.every_s:g} s; "
            f"sun visible in {result.visible}) and {out / 'truth.csv'}"
            + (" (interrupted: the span was cut short)" if result.interrupted else "")
        )
    else:
        print(
            f"wrote no frame: the sun stays below the horizon over the span (see --night); {out / 'truth.csv'}"
        )
    return 130 if result.interrupted else 0
