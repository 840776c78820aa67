"""``heliotrack simulate --realtime``: the default scenario on the wall clock.

The emulated drives, pyranometer, anemometer (with ``[wind]``) and sky run in real time;
the controller cycles on its configured period and polls the anemometer between cycles,
and (with ``--sunspec``) a SunSpec model 601 server publishes the plant to any SCADA
client and takes operator overrides as configured.

The emulated wind is ``[hil.wind]``'s, its days counted from the start of the run (the
anemometer emulator reads the monotonic clock): a storm day's storm comes 13 h into the
run, and storms at absolute times never.
"""

from __future__ import annotations

import asyncio
import sys
import time
from contextlib import ExitStack
from dataclasses import replace

import numpy as np

from controller.clock import RealClock
from controller.config import Config
from controller.northbound import Northbound
from controller.sunspec import SunSpecServer
from hil.sky import sky_series

from .devices import open_anemometer, open_drives, open_pyranometer
from .panel_loop import make_controller
from .scenario import as_scenario
from .sun_sources import build_sun_source
from .world import build_world


def run_realtime(
    config: Config, duration_s: float, sunspec: tuple[str, int] | None = None, out=sys.stdout
) -> dict:
    """Run for ``duration_s`` seconds of wall time; returns counts of what happened."""
    return asyncio.run(_run(config, duration_s, sunspec, out))


async def _run(config: Config, duration_s: float, sunspec, out) -> dict:
    config = as_scenario(config)
    hil = config.hil
    clock = RealClock()
    t0 = clock.now()
    grid = t0 + np.arange(0.0, duration_s + 120.0, 15.0)
    sky = sky_series(
        grid,
        config.site.latitude,
        config.site.longitude,
        config.site.altitude,
        {0: hil.skies[0]},
        hil.linke_turbidity,
        seed=hil.seed,
    )

    def ghi_at(t: float) -> float:
        return float(np.interp(t, grid, sky.ghi))

    counts = {"cycles": 0, "row_errors": 0, "overrides": 0}
    with ExitStack() as stack:
        # without the wind script the world has no anemometer, the controller none to poll,
        # and a [wind] plant ran unprotected with model 64601 empty (no reading, no alarm)
        wind = hil.wind.script(clock.monotonic()) if config.wind is not None else None
        world = build_world(config, hil, clock, stack, ghi_at, wind)
        sun, sensor = build_sun_source(config)
        controller = make_controller(
            as_scenario(config),
            world,
            lambda t: float(np.interp(t, grid, sky.beam_transmittance)),
            open_drives(config, world.links),
            sun,
            clock,
            realtime=True,
            sensor=sensor,
            pyranometer=open_pyranometer(config, world.links),
            anemometer=open_anemometer(config, world.links),
        )
        bridge = Northbound(controller, name=config.site.name or "heliotrack")
        if sunspec is not None:
            cfg = replace(config.sunspec, enabled=True, host=sunspec[0], port=sunspec[1])
            server = SunSpecServer.from_config(cfg, bridge.snapshot, bridge.on_override).start()
            stack.callback(server.stop)
            print(f"SUNSPEC {cfg.host}:{server.port}", file=out, flush=True)

        def on_cycle(records):
            counts["cycles"] += 1
            counts["row_errors"] += sum(1 for r in records if r.error)
            bridge.publish(records)
            counts["overrides"] += bridge.apply_pending()
            modes = ",".join(sorted({r.mode for r in records}))
            print(
                f"cycle {counts['cycles']} {time.strftime('%H:%M:%S')} {modes} errors={counts['row_errors']}",
                file=out,
                flush=True,
            )

        try:
            await controller.start()
            await controller.run(duration_s, on_cycle)
        finally:
            await controller.close()
    return counts
