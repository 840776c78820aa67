"""Fault injection in ``simulate``: the ``[hil.faults]`` of a scenario, switched on and off on
the simulated clock (see docs/faults.md).

:class:`FaultScheduler` plans every timed fault of the run at the start (the scheduled
ones, and the random ones as a seeded Poisson process per kind, each on a target drawn
among those it can hit), and :meth:`~FaultScheduler.advance` applies what is due whenever
the runner moves the clock: drive faults in the emulated firmware, an emulator killed and
restarted, CAN bus states, sensor faults, camera frames, wall-clock steps.  Wire faults
are rolled per reply by the world's injectors; the scheduler collects them and follows
every fault to its end in a :class:`~heliotrack.fault_ledger.FaultLedger`.  Faults are
always injected in the world, never by mocking the controller.
"""

from __future__ import annotations

import math
import random
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controller.clock import SimClock
from controller.records import CycleRecord
from controller.sun.camera import CameraFrame, FrameSource
from firmware_protocol import Mode, Status
from hil.camera.faults import damage

from .fault_kinds import AXIS_FAULTS, FAULT_DEFAULTS, FAULT_KINDS, WIRE_FAULTS
from .fault_ledger import FaultLedger
from .scenario import ScenarioConfig, fault_targets
from .world import World

__all__ = ["Fault", "FaultScheduler", "FaultyFrameSource", "unexpected_error"]


@dataclass
class Fault:
    """One timed fault of the plan (times in POSIX s of the simulation's true clock)."""

    kind: str
    start: float
    duration: float
    target: str
    magnitude: float = 0.0
    axis: int = 0
    rows: tuple[str, ...] = ()
    end: float = math.inf
    undo: Any = field(default=None, repr=False)


class FaultyFrameSource(FrameSource):
    """The world's camera, with the frame faults the scheduler switches on."""

    def __init__(self, inner: FrameSource, seed: int = 0):
        self.inner = inner
        self.kind: str | None = None
        self.rng = np.random.default_rng(seed)
        self.damaged: Counter[str] = Counter()

    def grab(self, t: float) -> CameraFrame | None:
        if self.kind == "camera_missing":
            self.damaged[self.kind] += 1
            return None
        frame = self.inner.grab(t)
        if frame is None or self.kind is None:
            return frame
        self.damaged[self.kind] += 1
        image = damage(self.kind, frame.image, self.rng)
        return None if image is None else CameraFrame(image, frame.time, frame.name)


class FaultScheduler:
    """Switches the faults of ``config.hil.faults`` on and off in ``world``.

    Parameters
    ----------
    config : the scenario
    world : its emulated world
    clock : the simulation's clock (wall-clock steps act on it)
    t0, t1 : the run's span, POSIX s
    camera : the world's camera, when the controller has one
    """

    def __init__(
        self,
        config: ScenarioConfig,
        world: World,
        clock: SimClock,
        t0: float,
        t1: float,
        camera: FaultyFrameSource | None = None,
    ):
        self.config = config
        self.spec = config.hil.faults
        self.world = world
        self.clock = clock
        self.camera = camera
        self.rng = random.Random(self.spec.seed)
        self.targets = fault_targets(config)
        self.by_link = {
            link.name: [tr for tr in config.trackers if tr.link == link.name] for link in config.links
        }
        self.ledger = FaultLedger([tr.name for tr in config.trackers], config.control.period_s)
        self.plan = sorted(self._scheduled() + self._random(t0, t1), key=lambda f: f.start)
        self._next = 0
        self.active: list[Fault] = []

    # -- planning -----------------------------------------------------------------------------
    def _scheduled(self) -> list[Fault]:
        out = []
        for ev in self.spec.events:
            target = ev.target or self._draw_target(ev.type)
            if target is None:
                continue
            mag = ev.magnitude if ev.magnitude is not None else self._draw_magnitude(ev.type)
            out.append(self._fault(ev.type, ev.start, ev.duration_s, target, mag))
        return out

    def _random(self, t0: float, t1: float) -> list[Fault]:
        out: list[Fault] = []
        busy: dict[tuple[str, str], float] = {}
        for rate in self.spec.random:
            if rate.per_hour <= 0 or not self.targets.get(rate.type):
                continue
            t = t0
            while True:
                t += self.rng.expovariate(rate.per_hour / 3600.0)
                if t >= t1:
                    break
                target = self._draw_target(rate.type)
                lo, hi = rate.durations()
                duration = self.rng.uniform(lo, hi)
                mag = self._draw_magnitude(rate.type, rate.magnitudes())
                if target is None or busy.get((rate.type, target), -math.inf) > t:
                    continue  # one fault of a kind on a target at a time
                busy[(rate.type, target)] = t + duration
                out.append(self._fault(rate.type, t, duration, target, mag))
        return out

    def _draw_target(self, kind: str) -> str | None:
        choices = self.targets.get(kind, ())
        if kind in WIRE_FAULTS:  # scheduled wire faults at random: a Modbus drive
            choices = tuple(c for c in choices if c in {tr.name for tr in self.config.trackers}) or choices
        return self.rng.choice(choices) if choices else None

    def _draw_magnitude(self, kind: str, rng: tuple[float, float] | None = None) -> float:
        lo, hi = rng or FAULT_DEFAULTS.get(kind, ((0.0, 0.0), (0.0, 0.0)))[1]
        mag = self.rng.uniform(lo, hi)
        if kind in ("wall_clock_step", "encoder_glitch") and self.rng.random() < 0.5:
            mag = -mag
        return mag

    def _fault(self, kind: str, start: float, duration: float, target: str, mag: float) -> Fault:
        trackers = {tr.name: tr for tr in self.config.trackers}
        if target in trackers:
            rows: tuple[str, ...] = (target,)
        elif target in self.by_link:
            rows = tuple(tr.name for tr in self.by_link[target])
        else:  # a sensor, the camera, the clock: the whole plant
            rows = tuple(trackers)
        axis = self.rng.randrange(trackers[target].axes) if target in trackers else 0
        return Fault(kind, start, duration, target, mag, axis, rows)

    # -- running ------------------------------------------------------------------------------
    def advance(self, t: float) -> None:
        """Apply every change due at ``t`` (the clock has just been moved there)."""
        t = float(t)
        while self._next < len(self.plan) and self.plan[self._next].start <= t:
            f = self.plan[self._next]
            self._next += 1
            f.start, f.end = t, t + f.duration  # it lasts its duration from when it is applied
            self._switch_on(f)
            self.ledger.started(f.kind, f.rows)
            self.active.append(f)
        still = []
        for f in self.active:
            if f.end <= t:
                f.undo()
                self.ledger.ended(f.kind, f.rows, t)
            else:
                still.append(f)
        self.active = still
        self.collect(t)

    def collect(self, t: float) -> None:
        """Take in the wire faults injected since the last call, stamped ``t``."""
        t = float(t)
        for name, wire in self.world.faults.wire.items():
            self._tally(name, [(e.kind, e.device_id) for e in wire.drain()], t)
        for name, can in self.world.faults.can.items():
            self._tally(name, [(e.kind, e.device_id) for e in can.drain()], t)

    def _tally(self, link: str, events: list[tuple[str, int]], t: float) -> None:
        if not events:
            return
        groups: Counter[tuple[str, tuple[str, ...]]] = Counter()
        for kind, device_id in events:
            groups[(kind, self._rows_of(link, device_id))] += 1
        for (kind, rows), n in groups.items():
            self.ledger.instant(kind, rows, t, n)

    def _rows_of(self, link: str, device_id: int) -> tuple[str, ...]:
        """The rows a reply of ``device_id`` on ``link`` belongs to: its drive's; on a CAN
        bus, a frame of no drive (the master's heartbeat, NMT) every row of the bus; a
        sensor's reply none (the sensor's next reading is its recovery)."""
        for tr in self.by_link.get(link, ()):
            if tr.device_id <= device_id < tr.device_id + tr.axes:
                return (tr.name,)
        if self.config.links_by_name[link].kind == "canopen":
            return tuple(tr.name for tr in self.by_link[link])
        return ()

    # -- the faults themselves -------------------------------------------------------------------
    def _switch_on(self, f: Fault) -> None:
        w = self.world
        kind = f.kind
        if kind in WIRE_FAULTS:
            self._force_wire(f)
        elif kind in AXIS_FAULTS:
            ax = w.firmwares[f.target].axes[f.axis]
            if kind == "drive_stall":
                ax.jammed = True
                f.undo = lambda: setattr(ax, "jammed", False)
            elif kind == "drive_overtemperature":
                ax.hot = True
                f.undo = lambda: setattr(ax, "hot", False)
            elif kind == "drive_overcurrent":
                ax.overloaded = True
                f.undo = lambda: setattr(ax, "overloaded", False)
            elif kind == "limit_switch":
                ax.trip_limit()
                f.undo = lambda: setattr(ax, "limit_stuck", False)
            else:
                ax.encoder_offset = f.magnitude
                f.undo = lambda: setattr(ax, "encoder_offset", 0.0)
        elif kind == "emulator_restart":
            w.kill(f.target)
            f.undo = lambda: w.restart(f.target)
        elif kind in ("can_error_passive", "can_bus_off"):
            bus = w.faults.can[f.target]
            bus.state = "bus_off" if kind == "can_bus_off" or bus.state == "bus_off" else "error_passive"
            f.undo = lambda: self._can_state(f.target)
        elif kind.startswith(("pyranometer_", "anemometer_")):
            self._sensor(f)
        elif kind.startswith("camera_"):
            cam = self.camera
            if cam is not None:
                cam.kind = kind
                f.undo = lambda: setattr(cam, "kind", None)
        elif kind == "wall_clock_step":
            self.clock.step_wall(f.magnitude)
            f.undo = lambda: self.clock.step_wall(-f.magnitude)
        if f.undo is None:
            f.undo = lambda: None

    def _can_state(self, link: str) -> None:
        """The CAN bus state left when a bus fault ends (another may still be on)."""
        others = {f.kind for f in self.active if f.target == link and f.end > self.clock.monotonic()}
        state = None
        if "can_bus_off" in others:
            state = "bus_off"
        elif "can_error_passive" in others:
            state = "error_passive"
        self.world.faults.can[link].state = state

    def _force_wire(self, f: Fault) -> None:
        trackers = {tr.name: tr for tr in self.config.trackers}
        device: int | None
        if f.target in trackers:
            link, device = trackers[f.target].link, trackers[f.target].device_id
        elif f.target in self.by_link:
            link, device = f.target, None
        else:  # a sensor
            sensor = self.config.pyranometer if f.target == "pyranometer" else self.config.wind
            assert sensor is not None
            link, device = sensor.link, sensor.device_id
        wire = self.world.faults.wire[link]
        wire.forced[device] = f.kind
        f.undo = lambda: wire.forced.pop(device, None)

    def _sensor(self, f: Fault) -> None:
        name, _, what = f.kind.partition("_")
        dev = self.world.pyranometer if name == "pyranometer" else self.world.anemometer
        if dev is None:
            return
        if what == "frozen":
            dev.frozen_at = self.clock.monotonic()
            f.undo = lambda: setattr(dev, "frozen_at", None)
        else:
            dev.override = math.nan if what == "nan" else f.magnitude
            f.undo = lambda: setattr(dev, "override", None)

    # -- judging a cycle ---------------------------------------------------------------------------
    def after_cycle(self, t: float, records: list[CycleRecord], weather_stow: bool) -> dict[str, bool]:
        """Judge the cycle at ``t`` (true time): which rows are in service (see
        :data:`~heliotrack.fault_ledger.DEFINITIONS`); returns that."""
        self.collect(t)
        ok = {rec.tracker: in_service(rec, self.world, weather_stow) for rec in records}
        self.ledger.judge(t, ok)
        return ok

    def summary(self) -> dict:
        out = self.ledger.summary(FAULT_KINDS, self.clock.monotonic())
        out["seed"] = self.spec.seed
        out["planned_timed"] = len(self.plan)
        if self.camera is not None:
            out["camera_frames_damaged"] = dict(self.camera.damaged)
        return out


def in_service(rec: CycleRecord, world: World, weather_stow: bool) -> bool:
    """The row did what the plant commanded this cycle (see the ledger's definitions)."""
    if rec.error or rec.health != "ok":
        return False
    fw = world.firmwares[rec.tracker]
    if any(fw.status(k) & Status.FAULT for k in range(len(fw.axes))):
        return False
    wanted = (Mode.STOW,) if weather_stow else (Mode.AUTO, Mode.MANUAL)
    return all(m in wanted for m in fw.modes)


_UNEXPECTED = re.compile(r"^(?P<row>.+?): (?P<exc>[A-Z][A-Za-z0-9_]*): ")


def unexpected_error(rec: CycleRecord) -> str | None:
    """The exception type of a row's error when it was not a link error but an exception
    the loop did not expect (its record reads ``"<row>: <Type>: <message>"``), else None."""
    m = _UNEXPECTED.match(rec.error)
    if m is None or m.group("row") != rec.tracker:
        return None
    return m.group("exc")
