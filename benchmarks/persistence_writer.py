"""The writing process of the persistence benchmark: commits state versions until killed.

``python -m benchmarks.persistence_writer STORE`` prints ``begin N`` before and ``done N``
after each commit of version N (flushed), with some history rows between commits.
"""

from __future__ import annotations

import sys

from controller.store import Store


def main(path: str) -> None:
    store = Store(path, check=False)
    rec = store.get_state("sunpath")
    v = rec.version if rec else 0
    payload = "x" * 2000  # a realistic state is a few kB of JSON
    while True:
        print(f"begin {v + 1}", flush=True)
        v = store.put_state("sunpath", {"version_written": v + 1, "payload": payload})
        print(f"done {v}", flush=True)
        store.add_setpoints(
            [(float(v), f"row-{i}", "TRACK", "ephemeris", [1.0 * i], [1.0 * i], "") for i in range(20)]
        )


if __name__ == "__main__":
    main(sys.argv[1])
