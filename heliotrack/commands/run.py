"""``heliotrack run``: the production loop on the wall clock, until SIGTERM or SIGINT.

Every link kind from the plant file (Modbus RTU on a serial device or pyserial URL, Modbus
TCP, CANopen through any python-can interface), the configured sun source (the ephemeris,
or a camera through the sun-path filter), the pyranometer, the anemometer (polled between
cycles) and the SunSpec server.  On the first signal every drive goes to its tracker's
``safe_position`` (confirmed by reading it back), the learned state is saved and the
process exits 0; a second signal, 0.5 s or more after the first, exits at once.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import os
import signal
import time
from collections import Counter
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from heliotrack.logs import add_log_options

if TYPE_CHECKING:
    from controller.config import Config
    from heliotrack.runtime import StateFolder

log = logging.getLogger("heliotrack.run")
#: A repeat of the stop signal sooner than this after the first is the same stop (s).
REPEAT_S = 0.5

#: After a stop is asked, how long a cycle in progress may take to finish (s).
CYCLE_GRACE_S = 0.5
#: How long the drives have to confirm their safe position (s).
SAFE_TIMEOUT_S = 3.0
#: Errors named in a cycle's line (all of them are in its JSON fields).
MAX_ERRORS_SHOWN = 5


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run the plant: the production loop on the wall clock",
        description="Drive the plant of a plant file on the wall clock until SIGTERM or SIGINT; "
        "then every drive goes to its safe position (stow or hold, per tracker), the learned "
        "state is saved, and the exit status is 0.  A second signal (0.5 s or more after the "
        "first) exits at once.  One log "
        "line per cycle at INFO, a warning for every fault (see docs/deploy.md).",
    )
    p.add_argument("--config", type=Path, required=True, help="plant TOML (see config/plant-example.toml)")
    p.add_argument(
        "--state",
        type=Path,
        default=None,
        metavar="DIR",
        help="folder for learned state and history: DIR/heliotrack.sqlite unless [store] path "
        "names a file, DIR/sunpath.json unless [sunpath] state does; one run per folder",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="stop after S seconds as on SIGTERM (default: run until a signal)",
    )
    add_log_options(p, top_level=False)
    p.set_defaults(func=run, default_log_level="INFO")


def run(args: argparse.Namespace) -> int:
    from controller.errors import ConfigError
    from heliotrack.allocator import bound_heap
    from heliotrack.bus_claims import claim_buses
    from heliotrack.runtime import claim_state_folder, load_plant, use_state_folder

    bound_heap()  # months of frames and arrays: no heap that keeps its high-water mark

    config = load_plant(args.config, "run")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(None, "--duration", "seconds > 0", args.duration)
    config, state = use_state_folder(config, args.state)
    # one run per folder, and one process per shared bus: two would fight over the drives
    with claim_state_folder(state), claim_buses(config.links):
        return asyncio.run(Service(config, state).serve(args.duration))


class Service:
    """One ``run``: the controller, its servers, the signals and the log lines."""

    def __init__(self, config: Config, state: StateFolder | None) -> None:
        self.config = config
        self.state = state
        self.stop: asyncio.Event | None = None
        self.stopped_by = ""
        self._first_signal = -math.inf
        self.tally: Counter[str] = Counter()
        self.camera_down = False
        self.ctl: Any = None
        self.bridge: Any = None
        self._foreign: frozenset[str] | None = None  # trackers on record in someone else's stow
        self._requests: dict[str, str] | None = None  # stow requests on record
        self._overrides: dict[str, list[float]] | None = None  # Manual overrides on record

    # -- signals -----------------------------------------------------------------------------
    def _on_signal(self, signum: int) -> None:
        name = signal.Signals(signum).name
        assert self.stop is not None
        if self.stop.is_set():
            if time.monotonic() - self._first_signal < REPEAT_S:
                # the same stop delivered twice (``timeout``, or a supervisor signalling the
                # process group): not an operator's second signal, so the drives still go safe
                log.info("%s again within %g s: taken as the same stop", name, REPEAT_S)
                return
            log.warning("second signal (%s): exiting at once", name)
            logging.shutdown()
            os._exit(128 + signum)
        self._first_signal = time.monotonic()
        self.stopped_by = name
        log.info("%s: stopping; every drive to its safe position", name)
        self.stop.set()

    # -- the service ---------------------------------------------------------------------------
    async def serve(self, duration: float | None) -> int:
        from controller.clock import RealClock
        from controller.closedloop.panel import ClosedLoopController
        from controller.loop import Controller
        from controller.store import open_store_or_none
        from heliotrack.devices import open_anemometer, open_drives, open_pyranometer
        from heliotrack.manual_overrides import restore_overrides
        from heliotrack.panel_loop import open_panel_cameras
        from heliotrack.runtime import resume_last_shutdown
        from heliotrack.stow_requests import restore_stow_requests
        from heliotrack.sun_sources import build_sun_source

        loop = asyncio.get_running_loop()
        self.stop = asyncio.Event()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, self._on_signal, sig)
        config, clock = self.config, RealClock()
        # in a thread: a camera's estimator takes seconds to build, signals stay heard
        sun, sensor = await asyncio.to_thread(build_sun_source, config, None, clock.now(), clock)
        server = store = None
        panels: dict = {}
        try:
            panels = open_panel_cameras(config, clock)
            if config.store.path is not None:
                store = open_store_or_none(config.store.path, log.warning)
            kind = partial(ClosedLoopController, panel_frames=panels) if panels else Controller
            ctl = self.ctl = kind(
                config,
                open_drives(config),
                sun,
                clock,
                realtime=True,
                sensor=sensor,
                pyranometer=open_pyranometer(config),
                anemometer=open_anemometer(config),
                store=store,
            )
            self._log_start(duration)
            resume_last_shutdown(ctl, self.state)
            folder = self.state.path if self.state is not None else None
            self._requests = restore_stow_requests(ctl, folder) if folder is not None else None
            self._overrides = restore_overrides(ctl, folder) if folder is not None else None
            server = self._sunspec(ctl)
            t0 = time.monotonic()
            crashed = await self._live(ctl, duration)
            from heliotrack.runtime import go_safe

            outcomes = await go_safe(ctl, SAFE_TIMEOUT_S, self.state)
            for o in outcomes:
                level = logging.INFO if o.confirmed else logging.WARNING
                log.log(level, "%s: %s", o.tracker, o.detail, extra={"fields": {"safe": vars(o)}})
            await ctl.close()  # saves what the sun-path filter learned
            self._log_summary(ctl, time.monotonic() - t0, outcomes)
            return 1 if crashed else 0
        finally:
            if server is not None:
                server.stop()
            if sensor is not None:
                sensor.close()
            for source in panels.values():
                source.close()
            if store is not None:
                store.close()

    async def _live(self, ctl, duration: float | None) -> bool:
        """Start and cycle until the stop (a signal or the end of ``duration``); True when
        the loop died of an unexpected error (logged with its traceback)."""
        assert self.stop is not None

        async def live() -> None:
            await ctl.start()
            await ctl.run(math.inf if duration is None else duration, self._on_cycle, self.stop)

        task = asyncio.ensure_future(live())
        stopper = asyncio.ensure_future(self.stop.wait())
        await asyncio.wait({task, stopper}, return_when=asyncio.FIRST_COMPLETED)
        if not self.stopped_by:
            self.stopped_by = "end of --duration"
        self.stop.set()
        stopper.cancel()
        if not task.done():
            await asyncio.wait({task}, timeout=CYCLE_GRACE_S)
        if not task.done():
            task.cancel()  # a cycle stuck on a dead drive, or the start-up
            await asyncio.wait({task})
        if not task.cancelled() and task.exception() is not None:
            exc = task.exception()
            log.error("the control loop failed: %s", exc, exc_info=exc)
            self.stopped_by = f"error: {type(exc).__name__}"
            return True
        return False

    def _sunspec(self, ctl):
        from controller.errors import ConfigError
        from controller.northbound import Northbound
        from controller.sunspec import SunSpecServer

        cfg = self.config.sunspec
        if not cfg.enabled:
            return None
        self.bridge = Northbound(ctl, name=self.config.site.name or "heliotrack")
        try:
            server = SunSpecServer.from_config(cfg, self.bridge.snapshot, self.bridge.on_override).start()
        except Exception as exc:  # noqa: BLE001 - a busy port or a foreign address: the user's to fix
            raise ConfigError(
                self.config.file, "sunspec.port", f"an address to serve on ({exc})", cfg.port
            ) from None
        log.info("SunSpec model 601 served on %s:%d", cfg.host, server.port)
        return server

    # -- log lines -------------------------------------------------------------------------------
    def _log_start(self, duration: float | None) -> None:
        from controller.drives.links import link_timing_warnings
        from controller.geometry.travel import travel_warnings

        c = self.config
        links = ", ".join(f"{link.name} ({link.kind})" for link in c.links)
        log.info(
            "heliotrack run: %d tracker(s) on %s; sun source %s; period %g s; state %s%s",
            len(c.trackers),
            links,
            c.control.sun_source,
            c.control.period_s,
            self.state.path if self.state else "not kept (no --state)",
            f"; for {duration:g} s" if duration else "",
        )
        for warning in travel_warnings(c) + link_timing_warnings(c):  # after the line that says what runs
            log.warning("%s", warning)

    def _on_cycle(self, records) -> None:
        from heliotrack.manual_overrides import note_overrides
        from heliotrack.runtime import note_foreign_stows
        from heliotrack.stow_requests import note_stow_requests

        ctl = self.ctl
        self._foreign = note_foreign_stows(ctl, self.state, self._foreign)
        if self.bridge is not None:
            self.bridge.publish(records)
            self.tally["overrides"] += self.bridge.apply_pending()
        folder = self.state.path if self.state else None
        self._requests = note_stow_requests(ctl, folder, self._requests)
        self._overrides = note_overrides(ctl, folder, self._overrides)
        modes = Counter(r.mode for r in records)
        errors = [r.error for r in records if r.error]
        source = records[0].source if records else "none"
        unwell = {r.tracker: r.health for r in records if r.health != "ok"}
        for r in records:
            self.tally[f"mode {r.mode}"] += 1
        for name, health in unwell.items():  # the mode is what was commanded, not what was done
            self.tally[f"health {name} {health}"] += 1
        self.tally[f"source {source}"] += 1
        self.tally["row errors"] += len(errors)
        camera = self._camera_outcome()
        looped = ctl.closedloop_cycle() if hasattr(ctl, "closedloop_cycle") else {}
        az, el = (records[0].sun_az_deg, records[0].sun_el_deg) if records else (math.nan, math.nan)
        text = ", ".join(f"{m} x{n}" if n > 1 else m for m, n in sorted(modes.items()))
        shown = "; ".join(errors[:MAX_ERRORS_SHOWN]) + (
            f"; and {len(errors) - MAX_ERRORS_SHOWN} more" if len(errors) > MAX_ERRORS_SHOWN else ""
        )
        log.info(
            "cycle %d: %s%s; sun %s (az %.2f, el %.2f)%s%s; %d error(s)%s",
            ctl.cycles,
            text,
            "".join(f"; {name} {health}" for name, health in sorted(unwell.items())),
            source,
            az,
            el,
            f"; camera {camera}" if camera else "",
            "; closed loop " + ", ".join(f"{k} {v}" for k, v in looped.items()) if looped else "",
            len(errors),
            (": " + shown) if errors else "",
            extra={
                "fields": {
                    "cycle": ctl.cycles,
                    "modes": dict(modes),
                    "not_ok": unwell,
                    "source": source,
                    "sun_az_deg": az,
                    "sun_el_deg": el,
                    "camera": camera,
                    "closedloop": looped,
                    "errors": errors,
                    "alarms": list(records[0].alarms) if records else [],
                }
            },
        )

    def _camera_outcome(self) -> str:
        """What the camera gave this cycle ("" when it was not read); one warning when it
        stops giving frames, one line when they are back."""
        sensor = self.ctl.sensor
        if sensor is None:
            return ""
        total = sum(sensor.outcomes.values())
        if total == self.tally["camera looks"]:
            return ""
        self.tally["camera looks"] = total
        outcome = sensor.last_outcome
        down = outcome.endswith("no frame")  # fused cameras: "<camera>: no frame"
        if down and not self.camera_down:
            self.camera_down = True
            hs = self.config.hotspot or self.config.fisheye
            log.warning("camera %s: no frame (none, or none recent)", hs.frames if hs else "")
        elif not down and self.camera_down:
            self.camera_down = False
            log.info("camera: frames again")
        return outcome

    def _log_summary(self, ctl, wall_s: float, outcomes) -> None:
        t = self.tally
        sources = {k.removeprefix("source "): v for k, v in t.items() if k.startswith("source ")}
        modes = {k.removeprefix("mode "): v for k, v in t.items() if k.startswith("mode ")}
        not_ok = {k.removeprefix("health "): v for k, v in t.items() if k.startswith("health ")}
        camera = dict(ctl.sensor.outcomes) if ctl.sensor is not None else {}
        stats = ctl.stats()
        safe = sum(o.confirmed for o in outcomes)
        fields = {
            "stopped_by": self.stopped_by,
            "cycles": ctl.cycles,
            "wall_s": round(wall_s, 1),
            "row_errors": t["row errors"],
            "link_errors": stats["errors"],
            "sensor_errors": stats["sensor_errors"],
            "sensors_down": dict(ctl.sensors_down),
            "modes": modes,
            "not_ok_cycles": not_ok,
            "sources": sources,
            "camera": camera,
            "overrides": t["overrides"],
            "safe_confirmed": safe,
            "drives": len(outcomes),
        }

        def dict_text(d: dict) -> str:
            return ", ".join(f"{k} {v}" for k, v in sorted(d.items())) or "none"

        log.info(
            "stopped (%s) after %d cycles in %.0f s: %d row errors, %d link errors, %d sensor errors; "
            "modes: %s%s; sources: %s%s; safe position confirmed for %d of %d drives",
            self.stopped_by,
            ctl.cycles,
            wall_s,
            t["row errors"],
            stats["errors"],
            stats["sensor_errors"],
            dict_text(modes),
            f" (cycles not ok: {dict_text(not_ok)})" if not_ok else "",
            dict_text(sources),
            f"; camera: {dict_text(camera)}" if ctl.sensor is not None else "",
            safe,
            len(outcomes),
            extra={"fields": fields},
        )
        for name, why in ctl.sensors_down.items():
            log.warning("%s still not answering at exit: %s", name, why)
        self._log_closedloop(ctl)

    @staticmethod
    def _log_closedloop(ctl) -> None:
        """One line per row in the panel-mounted closed loop: what it learned, what set its
        setpoints and what its camera gave."""
        summary = getattr(ctl, "closedloop_summary", None)
        if summary is None:
            return
        for name, row in summary()["rows"].items():
            learned = ", ".join(
                f"{axis} {v:+.3f} deg (sigma {row['learned_sigma_deg'][axis]:.3f})"
                for axis, v in row["learned_offset_deg"].items()
            )
            log.info(
                "closed loop %s: learned offset %s; setpoints %s; frames %s",
                name,
                learned,
                ", ".join(f"{k} {v}" for k, v in sorted(row["setpoints"].items())) or "none",
                ", ".join(f"{k} {v}" for k, v in sorted(row["frames"].items())) or "none",
                extra={"fields": {"closedloop": {name: row}}},
            )
