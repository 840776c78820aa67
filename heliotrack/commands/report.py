"""``heliotrack report DIR``: rebuild a run's report from its cycles.csv and summary.json."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="rebuild DIR/report/ (figures and index.html) from a run's outputs",
        description="Read DIR/cycles.csv and DIR/summary.json (written by simulate or replay; "
        "run writes none) and write the report: PNG figures and one self-contained index.html "
        "that opens offline.",
    )
    p.add_argument("dir", type=Path, metavar="DIR", help="the run's output folder")
    p.add_argument("--out", type=Path, default=None, help="where to write it (default DIR/report)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from heliotrack.output import check_out_dir
    from heliotrack.reports.run_report import write_report

    if args.out is not None:
        check_out_dir(args.out, files=("index.html",), folders=())
    print(f"wrote {write_report(args.dir, args.out)}")
    return 0
