"""Pacing the control loop: cycles on period boundaries, the anemometer polled between them.

On a simulated clock the clock is advanced.  In real time the schedule runs on the event
loop's monotonic clock (a wall-clock step moves neither the next cycle nor the end), and
the call returns at the end of ``duration_s`` whatever the period, so a server living
beside the loop (SunSpec) serves for the whole duration.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .loop import Controller
    from .records import CycleRecord


async def run_cycles(
    ctl: Controller,
    duration_s: float,
    on_cycle: Callable[[list[CycleRecord]], Any] | None = None,
    stop: asyncio.Event | None = None,
) -> dict[str, int]:
    """Cycle ``ctl`` for ``duration_s`` seconds, or until ``stop`` is set.

    ``on_cycle(records)`` is called after every cycle; a cycle that overruns its period
    makes the loop skip to the next boundary (counted in ``overruns``) rather than queue
    late cycles.  Returns ``{"cycles": ..., "overruns": ...}``.
    """
    if not ctl.realtime:
        return await _run_simulated(ctl, duration_s, on_cycle)
    loop = asyncio.get_running_loop()
    period = ctl.config.control.period_s
    end = loop.time() + duration_s
    next_cycle = loop.time()
    stop = stop or asyncio.Event()
    overruns = 0
    while not stop.is_set():
        now = loop.time()
        if now >= end:
            break
        if now >= next_cycle:
            records = await ctl.cycle()
            if on_cycle is not None:
                on_cycle(records)
            next_cycle += period
            while loop.time() > next_cycle:
                next_cycle += period
                overruns += 1
            continue
        wake = min(next_cycle, end)
        if ctl.anemometer is not None:
            if ctl.weather_due():
                await ctl.poll_weather()
                continue
            wake = min(wake, loop.time() + max(ctl.next_weather_poll - ctl.clock.monotonic(), 0))
        try:
            await asyncio.wait_for(stop.wait(), max(wake - loop.time(), 0.0))
        except TimeoutError:
            pass
    return {"cycles": ctl.cycles, "overruns": overruns}


async def _run_simulated(
    ctl: Controller, duration_s: float, on_cycle: Callable[[list[CycleRecord]], Any] | None
) -> dict[str, int]:
    period = ctl.config.control.period_s
    t_end = ctl.clock.now() + duration_s
    next_t = ctl.clock.now()
    while next_t < t_end:
        ctl.clock.sleep(max(next_t - ctl.clock.now(), 0.0))
        records = await ctl.cycle()
        if on_cycle is not None:
            on_cycle(records)
        next_t += period
    return {"cycles": ctl.cycles, "overruns": 0}
