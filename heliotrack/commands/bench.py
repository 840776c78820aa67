"""``heliotrack bench NAME|all``: run benchmarks and write JSON under benchmarks/results/."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    from benchmarks import BENCHMARKS

    p = sub.add_parser("bench", help="run a benchmark and write its JSON result")
    p.add_argument("name", choices=(*BENCHMARKS, "all"), help="benchmark to run")
    p.add_argument("--quick", action="store_true", help="smaller sizes, for a smoke run")
    p.add_argument("--kills", type=int, default=None,
                   help="persistence: how many times to kill the writer (default 1000)")
    p.add_argument("--days", type=int, default=None, help="soak: simulated days (default 30)")
    p.add_argument("--results-dir", type=Path, default=None,
                   help="where to write JSON (default benchmarks/results/)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks import BENCHMARKS, run_benchmark

    names = BENCHMARKS if args.name == "all" else (args.name,)
    for name in names:
        record = run_benchmark(name, quick=args.quick, results_dir=args.results_dir,
                               kills=args.kills, days=args.days)
        print(f"== {name} ({record['wall_s']} s) -> {record['path']}")
        print(json.dumps(record["result"], indent=2, default=str))
    return 0
