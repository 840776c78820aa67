"""Wind between control cycles: the anemometer read every ``[wind] poll_s`` and every drive
stowed at once when the wind says so (a mixin of :class:`controller.loop.Controller`)."""

from __future__ import annotations

import asyncio
import logging
import math
from typing import TYPE_CHECKING, Any, Protocol

from firmware_protocol import Command, Mode

from .drives.base import DriveCommError
from .weather import WindSample, WindState

if TYPE_CHECKING:
    from .clock import Clock
    from .config import Config
    from .records import TrackerRuntime
    from .safety import SafetyState

log = logging.getLogger("heliotrack.controller")


class WindSensor(Protocol):
    async def read(self, t: float) -> WindSample: ...
    async def close(self) -> None: ...


class WindPolling:
    """Needs ``config``, ``clock``, ``safety``, ``trackers``, ``anemometer``, ``sensor_errors``,
    ``_next_wind_poll``, ``_deadline()`` and ``_event()`` from the controller."""

    config: Config
    clock: Clock
    safety: SafetyState
    trackers: list[TrackerRuntime]
    anemometer: WindSensor | None
    sensor_errors: int
    _next_wind_poll: float

    def _deadline(self) -> float:  # pragma: no cover - the controller's
        raise NotImplementedError

    def _event(self, kind: str, **detail: Any) -> None:  # pragma: no cover - the controller's
        raise NotImplementedError

    @property
    def next_weather_poll(self) -> float:
        """When the anemometer is read next (the clock's monotonic time; inf without one)."""
        return self._next_wind_poll if self.anemometer is not None else math.inf

    def weather_due(self) -> bool:
        """True when the anemometer should be read now (every ``[wind] poll_s``)."""
        return self.anemometer is not None and self.clock.monotonic() >= self._next_wind_poll

    async def _poll_weather_if_due(self) -> None:
        if self.weather_due():
            await self.poll_weather()

    async def poll_weather(self) -> WindState:
        """Read the anemometer, update the wind stow, and stow (or resume) every drive at
        once when it changes.  Returns the wind state."""
        wind = self.config.wind
        if self.anemometer is None or wind is None:
            return self.safety.wind
        self._next_wind_poll = self.clock.monotonic() + wind.poll_s
        t = self.clock.now()
        try:
            sample: WindSample | None = await asyncio.wait_for(self.anemometer.read(t), max(wind.poll_s, 1.0))
        except (TimeoutError, DriveCommError) as exc:
            self.sensor_errors += 1
            log.warning("anemometer: %s", exc or "no answer")
            sample = None
        before = self.safety.wind
        state = self.safety.update_wind(t, sample)
        if state.alarm and not before.alarm:
            log.warning("WIND ALARM: %s", state.reason)
            self._event("wind_alarm", reason=state.reason, stow=state.stow)
        if state.stow and not before.stow:
            await self._stow_all(state.reason)
        elif before.stow and not state.stow:
            log.warning("wind stow over: resuming")
            self._event("wind_clear")
        return state

    async def _stow_all(self, reason: str) -> None:
        """Command STOW to every drive at once and read each back."""
        self._event("stow_commanded", reason=reason)

        async def one(tr: TrackerRuntime) -> None:
            try:
                await tr.drive.command(Command.STOW)
                tr.health.stowed_by_us = True
                st = await tr.drive.read_state()
                if all(a.mode in (Mode.STOW, Mode.MAINTENANCE) for a in st.axes):
                    self._event("stow_confirmed", tracker=tr.cfg.name)
            except DriveCommError as exc:
                log.warning("%s: wind stow command failed: %s", tr.cfg.name, exc)

        await asyncio.wait([asyncio.ensure_future(one(tr)) for tr in self.trackers], timeout=self._deadline())
