"""The loop's history in the store: every setpoint and sun observation, rotated by age.

A store that fails (disk full, a file put in the way) never stops the loop: the failure
is one warning line, repeated at most once an hour, and the loop goes on without history.
"""

from __future__ import annotations

import logging
import sqlite3
import time
from collections.abc import Iterable

from .records import CycleRecord
from .store import Store, StoreError
from .sun.types import SunObservation

log = logging.getLogger("heliotrack.controller")


class History:
    """Append-only history in ``store``; ``keep_days`` of it are kept."""

    def __init__(self, store: Store, keep_days: float = 30.0):
        self.store = store
        self.keep_s = keep_days * 86400.0
        self.failures = 0
        self._last_warning = -1e18

    def _guard(self, what: str, fn) -> None:
        try:
            fn()
        except (sqlite3.Error, StoreError, OSError, ValueError) as exc:
            self.failures += 1
            now = time.monotonic()
            if now - self._last_warning > 3600.0:
                self._last_warning = now
                log.warning("%s: %s not stored: %s", self.store.path, what, exc)

    def add_cycle(self, records: Iterable[CycleRecord]) -> None:
        rows = [(r.time, r.tracker, r.mode, r.source, r.targets_deg, r.actual_deg, r.error) for r in records]
        self._guard("setpoints", lambda: self.store.add_setpoints(rows))

    def add_observation(self, obs: SunObservation, accepted: bool) -> None:
        row = (obs.time, obs.sensor, obs.az_deg, obs.el_deg, obs.sigma_deg, accepted)
        self._guard("observation", lambda: self.store.add_observations([row]))

    def rotate(self, now: float) -> None:
        self._guard("rotation", lambda: self.store.rotate(self.keep_s, now))
