"""The soak's scenario run: ``simulate`` with every fault of the scenario, counting what must
not happen (crashes, commands outside the limits, setpoints lost, corrupt state) and how
the plant came back.  :mod:`benchmarks.soak` turns its tallies into ``soak.json``."""

from __future__ import annotations

import asyncio
import ctypes
import gc
import logging
import math
import os
import threading
import traceback
from collections import Counter
from pathlib import Path
from typing import Any

from controller.loop import Controller, CycleRecord
from controller.store import Store, StoreError
from controller.sunpath.state import StateError, load_from_store, load_state
from heliotrack.faults import unexpected_error
from heliotrack.simulate import ScenarioRun
from heliotrack.world import World

log = logging.getLogger("heliotrack.soak")


def rss_bytes(trim: bool = False) -> int:
    """Resident set size of this process now (Linux /proc).  ``trim``: first collect garbage
    and hand the allocator's free pages back to the system (glibc ``malloc_trim``), so that
    memory freed in the many threads' arenas does not count as held."""
    if trim:
        gc.collect()
        try:
            ctypes.CDLL("libc.so.6").malloc_trim(0)
        except (OSError, AttributeError):  # not glibc: measure as is
            pass
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def memory_breakdown() -> dict[str, float]:
    """Where the memory is, to explain a step in RSS: threads, Python objects tracked by the
    garbage collector, and glibc's heap (MB; all arenas: ``sbrk_mb`` from the main heap and
    the threads' heaps, ``mmap_mb`` in large blocks, ``in_use_mb`` allocated, ``free_mb``
    held free).  Empty values where the C library is not glibc 2.33+."""
    out: dict[str, float] = {"threads": threading.active_count(), "gc_objects": len(gc.get_objects())}
    try:
        fn = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return out
    fn.restype = _MallInfo2
    m = fn()
    mb = 2.0**-20
    out.update(
        sbrk_mb=round(m.arena * mb, 1),
        mmap_mb=round(m.hblkhd * mb, 1),
        in_use_mb=round((m.uordblks + m.hblkhd) * mb, 1),
        free_mb=round(m.fordblks * mb, 1),
    )
    return out


class SoakRun(ScenarioRun):
    """A :class:`~heliotrack.simulate.ScenarioRun` that keeps going through anything and
    counts it.  The learned state it validates after every day: the store of ``[store]
    path`` (its integrity check, and the sun-path state in it), else the ``[sunpath]
    state`` file."""

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.store_path: Path | None = self.config.store.path
        self.state_path: Path | None = self.config.sunpath.state
        self.crashes: Counter[str] = Counter()
        self.crash_samples: list[str] = []
        self.setpoints_checked = 0
        self.setpoints_lost = 0
        self.setpoints_lost_samples: list[str] = []
        self.state_checks = 0
        self.state_corruptions: list[str] = []
        self.rss_by_day: list[int] = []
        self.memory_by_day: list[dict[str, float]] = []
        self.wind_alarms: Counter[str] = Counter()
        self.loop_errors: Counter[str] = Counter()
        self.thread_errors: Counter[str] = Counter()
        self._writes: dict[str, tuple[int, int]] = {}
        self._faulted: set[str] = set()
        self._day = 0
        self._wall_day: int | None = None
        self.world: World | None = None
        self._alarm = False
        self.cycles_done = 0

    # -- keep going, and count ------------------------------------------------------------------
    async def run(self) -> dict:
        loop = asyncio.get_running_loop()
        loop.set_exception_handler(self._loop_error)
        previous = threading.excepthook
        threading.excepthook = self._thread_error
        try:
            return await super().run()
        finally:
            threading.excepthook = previous

    def _loop_error(self, loop: asyncio.AbstractEventLoop, context: dict) -> None:
        """An exception the event loop caught for a library (a transport closed after data
        it could not decode): handled by the library, counted here, not a crash."""
        exc = context.get("exception")
        self.loop_errors[type(exc).__name__ if exc else context.get("message", "?")[:60]] += 1

    def _thread_error(self, args: threading.ExceptHookArgs) -> None:
        self.thread_errors[args.exc_type.__name__] += 1

    def _crash(self, where: str, exc: BaseException) -> None:
        self.crashes[f"{where}: {type(exc).__name__}"] += 1
        if len(self.crash_samples) < 20:
            tb = traceback.format_exception(exc)
            self.crash_samples.append(f"{where}: {''.join(tb[-3:]).strip()}")
        log.error("soak: %s raised %s: %s", where, type(exc).__name__, exc)

    async def _cycle(self, controller: Controller) -> list[CycleRecord]:
        world = self.world
        # a drive in FAULT when the cycle starts cannot take a set-point (CiA 402 refuses one
        # outside OPERATION ENABLED): its targets are not expected in this cycle
        self._faulted = (
            {n for n, fw in world.firmwares.items() if any(fw.fault(k) for k in range(len(fw.axes)))}
            if world is not None
            else set()
        )
        try:
            records = await super()._cycle(controller)
        except Exception as exc:  # noqa: BLE001 - a crash: counted, the run goes on
            self._crash("cycle", exc)
            return []
        self._note_alarm(controller)
        return records

    async def _poll(self, controller: Controller) -> None:
        try:
            await super()._poll(controller)
        except Exception as exc:  # noqa: BLE001 - a crash: counted, the run goes on
            self._crash("poll_weather", exc)
        self._note_alarm(controller)

    def _note_alarm(self, controller: Controller) -> None:
        wind = controller.safety.wind
        if wind.alarm and not self._alarm:
            self.wind_alarms["storm" if wind.reason.startswith("wind") else "anemometer"] += 1
        self._alarm = wind.alarm

    # -- after every cycle ----------------------------------------------------------------------
    def _after_cycle(self, records: list[CycleRecord], controller: Controller, world: World) -> None:
        self.world = world
        self.cycles_done += 1
        faults = self.faults
        if faults is not None:
            faults.collect(self.clock.monotonic())
            reachable = {r: faults.ledger.reachable(r) and faults.ledger.after_faults(r) for r in self.tally}
        else:
            reachable = {r: True for r in self.tally}
        for rec in records:
            exc = unexpected_error(rec)
            if exc is not None:
                self._crash(f"row {rec.tracker}", RuntimeError(f"{exc}: {rec.error}"))
        self._check_setpoints(records, world, reachable)
        super()._after_cycle(records, controller, world)
        day = int((self.clock.monotonic() - self.t0) // 86400)
        if day != self._day or self.cycles_done == self.n_cycles:
            self._day = day
            self.rss_by_day.append(rss_bytes(trim=True))
            self.memory_by_day.append(memory_breakdown())
        wall_day = int(self.clock.now() // 86400)
        if self._wall_day is not None and wall_day != self._wall_day:
            self._check_state()  # the controller saves when its (UTC) day changes
        self._wall_day = wall_day

    def _check_setpoints(self, records: list[CycleRecord], world: World, reachable: dict[str, bool]) -> None:
        """A reachable drive, after a fault that touched it cleared, must have received this
        cycle's targets (a write per axis, the values of the record)."""
        for rec in records:
            fw = world.firmwares[rec.tracker]
            before_id, before = self._writes.get(rec.tracker, (id(fw), 0))
            writes = fw.target_writes - (before if before_id == id(fw) else 0)
            self._writes[rec.tracker] = (id(fw), fw.target_writes)
            if not reachable.get(rec.tracker, False) or rec.tracker in self._faulted:
                continue
            self.setpoints_checked += 1
            got = not rec.error and writes >= len(fw.axes)
            if got and rec.targets_deg:
                got = all(
                    w is not None and abs(w - t) <= 0.002
                    for w, t in zip(fw.last_target_written, rec.targets_deg)
                )
            if not got:
                self.setpoints_lost += 1
                if len(self.setpoints_lost_samples) < 20:
                    self.setpoints_lost_samples.append(
                        f"{rec.tracker} at {rec.time:.0f}: {writes} target writes, last "
                        f"{fw.last_target_written}, record {rec.targets_deg}, modes "
                        f"{[m.name for m in fw.modes]}, error {rec.error[:120]!r}"
                    )

    def _check_state(self) -> None:
        """The learned state the controller just saved must load and pass validation."""
        if self.store_path is None and self.state_path is None:
            return
        self.state_checks += 1
        try:
            if self.store_path is not None:
                with Store(self.store_path, check=True) as store:
                    load_from_store(store, now=self.clock.now())
            elif self.state_path is not None:
                load_state(self.state_path, now=self.clock.now())
        except (StateError, StoreError) as exc:
            self.state_corruptions.append(str(exc))

    # -- results ------------------------------------------------------------------------------------
    def rss_growth_pct(self) -> float | None:
        r = self.rss_by_day
        return round(100.0 * (r[-1] - r[0]) / r[0], 2) if len(r) >= 2 else None

    def out_of_limit_samples(self) -> list[str]:
        """What the drives noted of the targets written outside the limits (the first few
        per drive, any drive that ran in the soak)."""
        fws = self.world.all_firmwares() if self.world is not None else []
        return [
            f"t={t:.0f} axis {k}: {v:.3f} deg outside {lim}, the drive's soft limits then {soft}"
            for fw in fws
            for t, k, v, lim, soft in fw.out_of_limit_samples
        ][:20]

    def out_of_limit(self) -> tuple[int, int]:
        """(targets written outside the limits, targets written), over every drive."""
        fws = self.world.all_firmwares() if self.world is not None else []
        return sum(fw.out_of_limit_writes for fw in fws), sum(fw.target_writes for fw in fws)


def finite(x: float | None) -> float | None:
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else x
