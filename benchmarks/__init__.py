"""Benchmarks: speed and accuracy targets, run by ``heliotrack bench NAME``.

Each benchmark is a module ``benchmarks/<name>.py`` exposing ``run(quick: bool) -> dict``
(plus an optional ``DESCRIPTION``).  The runner stamps the result with the machine and the
time and writes ``benchmarks/results/<name>.json``.  ``quick`` trims sizes for a smoke
run; published figures come from full runs.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import platform
import time
from datetime import UTC, datetime
from pathlib import Path

from controller.atomic import atomic_write
from heliotrack.resources import writable_home

#: Registered benchmarks (module names under ``benchmarks``).
BENCHMARKS: tuple[str, ...] = (
    "loop",
    "plant",
    "sunpath",
    "skytype",
    "diffuse",
    "hotspot",
    "persistence",
    "fisheye",
    "fisheye_third",
    "fisheye_third_clouds",
    "fisheye_fourth",
    "fisheye_selfcal",
    "soak",
)

RESULTS_DIR = writable_home("benchmarks/results")  # the checkout's, or under the working directory


def run_benchmark(name: str, quick: bool = False, results_dir: Path | None = None, **options: object) -> dict:
    """Run one benchmark and write its JSON; return the result dict.

    ``options`` (e.g. ``kills``, ``days``) go to the benchmark's ``run`` when it takes them.
    """
    if name not in BENCHMARKS:
        raise KeyError(name)
    module = importlib.import_module(f"benchmarks.{name}")
    accepted = inspect.signature(module.run).parameters
    kwargs = {k: v for k, v in options.items() if v is not None and k in accepted}
    t0 = time.perf_counter()
    result = module.run(quick=quick, **kwargs)
    record = {
        "benchmark": name,
        "quick": quick,
        "finished_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "wall_s": round(time.perf_counter() - t0, 3),
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
        },
        "result": result,
    }
    out_dir = results_dir or RESULTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)

    # a size other than the default is another result, not the benchmark's (soak-10d.json)
    def default(k: str) -> object:  # the size the run takes without the option, quick or not
        full = getattr(module, k.upper(), accepted[k].default)
        return getattr(module, f"QUICK_{k.upper()}", full) if quick else full

    sizes = "".join(_SIZE_NAMES.get(k, f"-{k}{{}}").format(v) for k, v in kwargs.items() if v != default(k))
    path = out_dir / f"{name}{sizes}{'-quick' if quick else ''}.json"
    atomic_write(path, json.dumps(record, indent=2, default=_json_default) + "\n")
    record["path"] = str(path)
    return record


#: How a non-default size names its result file.
_SIZE_NAMES = {"days": "-{}d", "kills": "-kills{}"}


def _json_default(obj):
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
