"""``heliotrack bench [NAME ...]``: run benchmarks, write JSON under benchmarks/results/,
print the headline figures beside their targets, and exit 1 when one misses."""

from __future__ import annotations

import argparse
from pathlib import Path

from heliotrack.argtypes import int_in


def register(sub: argparse._SubParsersAction) -> None:
    from benchmarks import BENCHMARKS

    p = sub.add_parser(
        "bench",
        help="run benchmarks (all when no name is given)",
        description="Run benchmarks and write benchmarks/results/<name>.json; "
        "with no name, run every one and write summary.md.  Exit "
        "status 1 when a figure misses its target.",
    )
    p.add_argument(
        "names",
        nargs="*",
        metavar="NAME",
        choices=(*BENCHMARKS, "all", []),
        help=f"benchmarks to run ({', '.join(BENCHMARKS)}); default: all",
    )
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke run")
    p.add_argument(
        "--summary-only", action="store_true", help="run nothing: rebuild summary.md from the results on disk"
    )
    p.add_argument(
        "--kills",
        type=int_in(1, 100_000),
        default=None,
        help="persistence: how many times to kill the writer (default 1000; another count "
        "is written as persistence-kills<N>.json)",
    )
    p.add_argument(
        "--days",
        type=int_in(1, 3660),
        default=None,
        help="soak: simulated days (default 30; another count is written as soak-<N>d.json)",
    )
    p.add_argument(
        "--results-dir", type=Path, default=None, help="where to write JSON (default benchmarks/results/)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    from benchmarks import BENCHMARKS, RESULTS_DIR, run_benchmark
    from benchmarks.summary import headlines, load_results, markdown, table
    from controller.atomic import atomic_write
    from heliotrack.output import check_out_dir

    names = [n for n in args.names if n != "all"] or list(BENCHMARKS)
    # before a run that may take 18 minutes, not after it
    results_dir = check_out_dir(args.results_dir or RESULTS_DIR, "--results-dir", files=(), folders=())
    rows = []
    if not args.summary_only:
        from tqdm import tqdm

        # a bar over the benchmarks when stderr is a terminal, silent otherwise
        bar = tqdm(names, desc="bench", unit="benchmark", disable=not sys.stderr.isatty(), leave=False)
        for name in bar:
            bar.set_postfix_str(name)
            record = run_benchmark(
                name, quick=args.quick, results_dir=args.results_dir, kills=args.kills, days=args.days
            )
            bar.write(f"== {name} ({record['wall_s']} s) -> {record['path']}", file=sys.stdout)
            found = headlines(name, record["result"])
            bar.write(table(found), file=sys.stdout)
            rows += found
        bar.close()
    else:
        for name, rec in load_results(names, results_dir).items():
            rows += headlines(name, rec["result"]) if rec else []
    if not args.names or "all" in args.names or args.summary_only:
        path = atomic_write(results_dir / "summary.md", markdown(load_results(list(BENCHMARKS), results_dir)))
        print(f"wrote {path}")
    misses = [r for r in rows if r.ok is False]
    if misses:
        print(f"{len(misses)} figure(s) missed their target:", file=sys.stderr)
        for r in misses:
            print(f"  {r.benchmark}: {r.figure} = {r.value} (target {r.target})", file=sys.stderr)
        return 1
    return 0
