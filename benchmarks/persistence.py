"""Power-loss safety of the store: kill a writing process at random moments, reopen.

A child process (``benchmarks.persistence_writer``) commits new versions of a state
document as fast as it can; the parent kills it with SIGKILL at a random moment (a power
cut as far as the process is concerned: nothing is flushed after the signal), reopens the
store with the integrity check, and compares what it finds with what the child reported:
the version must be the last one whose commit returned (``done N``), or the one in flight
(``begin N+1`` without ``done``) if that commit reached the disk.  Anything else, a failed
integrity check or a document that does not decode, is a corruption.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DESCRIPTION = "store survival: SIGKILL a writer at random moments, reopen, compare"
TARGETS = {"corruptions": 0, "at_last_commit_fraction": 1.0}


def one_kill(path: Path, rng: np.random.Generator, committed: int = 0) -> dict:
    """Start a writer on ``path``, kill it after a random delay, reopen and judge.

    ``committed``: the version found after the previous kill (the writer resumes from it).
    """
    from controller.store import Store, StoreError

    env = dict(os.environ, PYTHONUNBUFFERED="1")
    child = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.persistence_writer", str(path)],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=Path(__file__).resolve().parents[1],
    )
    assert child.stdout is not None
    first = child.stdout.readline()  # the writer is up and committing
    time.sleep(float(rng.uniform(0.0, 0.05)))
    os.kill(child.pid, signal.SIGKILL)
    rest = child.stdout.read()
    child.wait()
    done = begun = committed
    for line in (first + rest).splitlines():
        word, _, n = line.partition(" ")
        if word == "done":
            done = int(n)
        elif word == "begin":
            begun = int(n)
    try:
        with Store(path) as store:
            rec = store.get_state("sunpath")
        found = rec.version if rec else 0
        ok_body = rec is None or rec.body.get("version_written") == rec.version
    except StoreError as exc:
        return {"corrupt": True, "reason": str(exc), "done": done, "found": None}
    at_last = found == done or (begun == done + 1 and found == begun)
    return {
        "corrupt": not ok_body or found < done or found > max(done, begun),
        "at_last_commit": at_last,
        "done": done,
        "found": found,
    }


#: Kills of a full run and of a quick one (``--kills`` changes either).
KILLS = 1000
QUICK_KILLS = 20


def run(quick: bool = False, kills: int | None = None) -> dict:
    n = kills if kills is not None else (QUICK_KILLS if quick else KILLS)
    rng = np.random.default_rng(1)
    outcomes = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "store.sqlite"
        committed = 0
        for _ in range(n):
            outcomes.append(one_kill(path, rng, committed))
            committed = outcomes[-1]["found"] or committed
    corrupt = [o for o in outcomes if o["corrupt"]]
    return {
        "targets": TARGETS,
        "kills": n,
        "corruptions": len(corrupt),
        "at_last_commit": sum(1 for o in outcomes if o.get("at_last_commit")),
        "versions_committed": outcomes[-1]["found"] if outcomes else 0,
        "in_flight_commits_found_on_disk": sum(1 for o in outcomes if o.get("found") == o["done"] + 1),
        "corruption_examples": corrupt[:5],
        "seconds": round(time.perf_counter() - t0, 1),
        "definitions": {
            "corruption": "integrity check failed, state not JSON, or a version other than "
            "the last committed or the one in flight",
            "at_last_commit": "reopened at the last version whose commit returned, or at the "
            "one in flight when the kill came after it reached the disk",
        },
        "passed": len(corrupt) == 0 and all(o.get("at_last_commit") for o in outcomes),
    }
