"""What became of every injected fault: counted by kind, and survived once the rows it
touched were back in service after it cleared.

The scheduler (:mod:`heliotrack.faults`) reports each fault when it starts and when it
clears, with the rows (trackers) it touches; after every control cycle the runner says
which rows are in service.  A row is back once it is in service in a cycle at or after
the clearing of the last fault that touched it; a fault has survived once every row it
touched is back.  Recovery is measured from that last clearing, in control periods.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

#: Faults that cut a row off the controller while they last (its setpoints cannot arrive).
BLOCKING = frozenset({"emulator_restart", "can_bus_off", "can_error_passive"})
#: Faults of the plant's sensors, camera or clock: judged on the whole plant.
PLANT_KINDS_PREFIX = ("pyranometer_", "anemometer_", "camera_", "wall_clock_")

DEFINITIONS = {
    "injected": "faults switched on (timed faults) or applied to a reply or frame (wire faults)",
    "survived": "faults after whose clearing every row they touched was in service again "
    "before the run ended",
    "in_service": "a cycle in which the row's exchange succeeded, its health was ok, its drive "
    "had no latched fault and was in the mode the plant commanded (STOW in a weather stow, "
    "AUTO otherwise)",
    "open_at_end": "faults still on at the end of the run, or cleared less than two control "
    "periods before it (not counted as lost)",
    "recovery_periods": "control periods from the clearing of the last fault that touched a row "
    "to its next cycle in service (0: the cycle at the clearing itself)",
}


@dataclass
class _Pending:
    kind: str
    n: int
    rows: set[str]


@dataclass
class _Row:
    active: int = 0  # faults on now
    blocked: int = 0  # of which cut it off
    waiting: bool = False  # a fault cleared, not in service since
    since: float = -math.inf  # when the last fault touching it cleared


@dataclass
class FaultLedger:
    """Counts and survival of faults, by kind.

    Parameters
    ----------
    rows : names of every tracker
    period_s : the control period
    """

    rows: Iterable[str]
    period_s: float
    injected: Counter[str] = field(default_factory=Counter)
    survived: Counter[str] = field(default_factory=Counter)
    recovery_worst_s: dict[str, float] = field(default_factory=dict)
    #: Rows hit by a wire fault since the last cycle's judgement.
    hit: set[str] = field(default_factory=set)
    #: The slowest recovery of any row: its row, the faults it waited for, when the last
    #: of them cleared and when the row was back (POSIX s on the simulated clock).
    worst_event: dict | None = None

    def __post_init__(self) -> None:
        self.state = {r: _Row() for r in self.rows}
        self._pending: list[_Pending] = []

    # -- reports from the scheduler ----------------------------------------------------------
    def started(self, kind: str, rows: Iterable[str]) -> None:
        """A timed fault went on, touching ``rows``."""
        self.injected[kind] += 1
        for r in rows:
            s = self.state[r]
            s.active += 1
            s.blocked += kind in BLOCKING

    def cleared(self, kind: str, rows: Iterable[str], t: float, n: int = 1) -> None:
        """A timed fault went off at ``t`` (or ``n`` wire faults hit ``rows`` at ``t``)."""
        rows = set(rows)
        if not rows:  # touched no row (a sensor's reply): nothing to come back
            self.survived[kind] += n
            return
        for r in rows:
            s = self.state[r]
            s.waiting, s.since = True, max(s.since, t)
        self._pending.append(_Pending(kind, n, rows))

    def ended(self, kind: str, rows: Iterable[str], t: float) -> None:
        """The end of a timed fault reported by :meth:`started`."""
        rows = list(rows)
        for r in rows:
            s = self.state[r]
            s.active -= 1
            s.blocked -= kind in BLOCKING
        self.cleared(kind, rows, t)

    def instant(self, kind: str, rows: Iterable[str], t: float, n: int = 1) -> None:
        """``n`` wire faults of ``kind`` hit ``rows`` at ``t``."""
        rows = list(rows)
        self.injected[kind] += n
        self.hit.update(rows)
        self.cleared(kind, rows, t, n)

    # -- the runner's judgement ----------------------------------------------------------------
    def reachable(self, row: str) -> bool:
        """No fault cuts the row off now, and no wire fault hit it since the last judgement."""
        return self.state[row].blocked == 0 and row not in self.hit

    def after_faults(self, row: str) -> bool:
        """Some fault touching the row has cleared before."""
        return self.state[row].since > -math.inf

    def judge(self, t: float, in_service: Mapping[str, bool]) -> None:
        """The rows in service in the cycle at ``t``; resolves what they were waiting for."""
        back: dict[str, float] = {}
        for r, ok in in_service.items():
            s = self.state[r]
            if ok and s.waiting and s.active == 0 and s.since <= t + 1e-9:
                back[r] = t - s.since
                s.waiting = False
        self.hit.clear()
        if not back:
            return
        for r, dt in back.items():
            if self.worst_event is None or dt > self.worst_event["seconds"]:
                kinds = sorted({p.kind for p in self._pending if r in p.rows})
                self.worst_event = {
                    "row": r,
                    "faults": kinds,
                    "cleared_at": round(t - dt, 3),
                    "back_at": round(t, 3),
                    "seconds": round(dt, 3),
                }
        keep = []
        for p in self._pending:
            for r in p.rows & back.keys():
                p.rows.discard(r)
                worst = self.recovery_worst_s.get(p.kind, 0.0)
                self.recovery_worst_s[p.kind] = max(worst, back[r])
            if p.rows:
                keep.append(p)
            else:
                self.survived[p.kind] += p.n
        self._pending = keep

    # -- results ----------------------------------------------------------------------------------
    def open_at_end(self, t: float) -> Counter[str]:
        """Faults not resolved at ``t`` (the run's end) that had no fair chance: still on,
        or cleared less than two control periods before ``t``."""
        out: Counter[str] = Counter()
        for p in self._pending:
            if any(t - self.state[r].since < 2 * self.period_s for r in p.rows):
                out[p.kind] += p.n
        return out

    def summary(self, kinds: Iterable[str], t_end: float | None = None) -> dict:
        still = self.open_at_end(t_end) if t_end is not None else Counter()
        per = {
            k: {
                "injected": self.injected.get(k, 0),
                "survived": self.survived.get(k, 0),
                "open_at_end": still.get(k, 0),
                "recovery_worst_periods": (
                    round(self.recovery_worst_s[k] / self.period_s, 3) if k in self.recovery_worst_s else None
                ),
            }
            for k in kinds
        }
        return {
            "injected": sum(self.injected.values()),
            "survived": sum(self.survived.values()),
            "open_at_end": sum(still.values()),
            "by_type": per,
            "definitions": DEFINITIONS,
        }

    def worst_periods(self, plant: bool = False) -> float | None:
        """Worst recovery, in periods, of the faults of drives and links (``plant``: of the
        plant's sensors, camera and clock)."""
        vals = [
            v / self.period_s
            for k, v in self.recovery_worst_s.items()
            if k.startswith(PLANT_KINDS_PREFIX) == plant
        ]
        return round(max(vals), 3) if vals else None
