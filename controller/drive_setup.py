"""Drives brought into service and kept there: connect, identify, configure (watchdog,
soft limits, stow angles), heartbeats, a reboot noticed and configured again, and whose
stow a drive found stowed is in (a mixin of :class:`controller.loop.Controller`)."""

from __future__ import annotations

import asyncio
import logging
import math
from typing import TYPE_CHECKING, Any

from firmware_protocol import Mode, Status

from .drives.base import DriveCommError, DriveHeld, DriveIdentity, DriveState
from .safety import drive_stow_angles

if TYPE_CHECKING:
    from .clock import Clock
    from .config import Config
    from .records import TrackerRuntime
    from .safety import SafetyState

log = logging.getLogger("heliotrack.controller")


class DriveSetup:
    """Needs ``config``, ``clock``, ``safety``, ``trackers``, ``START_TIMEOUT_S``,
    ``_event()`` and ``_link_failed()`` from the controller."""

    config: Config
    clock: Clock
    safety: SafetyState
    trackers: list[TrackerRuntime]
    START_TIMEOUT_S: float

    def _event(self, kind: str, **detail: Any) -> None:  # pragma: no cover - the controller's
        raise NotImplementedError

    def _link_failed(self, tr: TrackerRuntime, why: str, held: bool = False) -> None:  # pragma: no cover
        raise NotImplementedError

    async def start(self) -> None:
        """Connect and configure every drive (limits, stow angles, watchdog).

        A drive that fails here is recorded and retried by the next cycles; the others
        start regardless.
        """
        await asyncio.gather(*(self._start_one(tr) for tr in self.trackers))

    async def _start_one(self, tr: TrackerRuntime) -> None:
        try:
            await asyncio.wait_for(self._configure(tr), self.START_TIMEOUT_S)
        except (TimeoutError, DriveCommError) as exc:
            tr.errors += 1
            self._link_failed(tr, str(exc) or "no answer at start-up", held=isinstance(exc, DriveHeld))
        except Exception as exc:  # noqa: BLE001 - one drive's failure must not stop the others' start
            tr.errors += 1
            log.debug("%s: start-up failed", tr.cfg.name, exc_info=True)
            self._link_failed(tr, f"{type(exc).__name__}: {exc}")

    def _unheard(self, tr: TrackerRuntime) -> bool:
        """The drive has not answered an exchange for longer than its watchdog allows (it has
        stowed itself since); False before its first answer."""
        silent = self.clock.monotonic() - tr.health.last_ok
        return math.isfinite(silent) and silent >= self.config.control.heartbeat_timeout_s

    @staticmethod
    def _note_watchdog_stow(tr: TrackerRuntime, st: DriveState, unheard: bool = False) -> None:
        """A STOW is the drive's watchdog's (ours to resume) when it says COMM_LOST or
        WATCHDOG_STOW, or went unheard longer than its watchdog allows or rebooted (``unheard``;
        a heartbeat, even another drive's on CAN, clears COMM_LOST at once, and older firmware
        has no WATCHDOG_STOW); a stow last seen as someone else's, only on WATCHDOG_STOW."""
        latched = any(a.status & Status.WATCHDOG_STOW for a in st.axes)
        lost = unheard or any(a.status & Status.COMM_LOST for a in st.axes)
        if any(a.mode == Mode.STOW for a in st.axes) and (latched or (lost and not tr.health.foreign_stow)):
            tr.health.watchdog_stow = True

    async def _configure(self, tr: TrackerRuntime, rebooted: bool = False, connected: bool = False) -> None:
        # until it succeeds the drive is not in service: a configuration that failed after a
        # reboot would otherwise leave it on its factory watchdog and limits, reported ok
        tr.configured = False
        if not connected:
            await tr.drive.connect()
        if tr.drive.axis_count != tr.cfg.axes:
            # a single-axis row on a dual-axis drive had been configured with the row's
            # limits on the azimuth axis and refused by it, every cycle
            raise DriveCommError(
                f"{tr.cfg.name}: drive has {tr.drive.axis_count} "
                f"{'axis' if tr.drive.axis_count == 1 else 'axes'}, a {tr.cfg.type} tracker "
                f"drives {tr.cfg.axes}: wrong device_id?"
            )
        # Before our first heartbeat: a drive its watchdog stowed still says COMM_LOST.
        self._note_watchdog_stow(tr, await tr.drive.read_state(), rebooted or self._unheard(tr))
        tr.uptime_s = None
        await tr.drive.configure(
            heartbeat_timeout_s=self.config.control.heartbeat_timeout_s,
            soft_limits=tr.cfg.soft_limits,
            stow_angles=drive_stow_angles(self.safety, tr.cfg),
        )
        tr.restarts_seen = tr.drive.restarts
        await self._heartbeat(tr, force=True)
        # Spread the rows' heartbeats over the interval so they do not all fall on one cycle.
        tr.last_heartbeat -= (tr.index % 3) * self.config.control.heartbeat_timeout_s / 9
        tr.configured = True

    async def _heartbeat(self, tr: TrackerRuntime, force: bool = False) -> None:
        # Three heartbeats per watchdog timeout are plenty and spare the bus.
        t = self.clock.monotonic()
        timeout = self.config.control.heartbeat_timeout_s
        if force or t - tr.last_heartbeat >= timeout / 3 - 1e-9:
            # the identity and uptime read with the heartbeat (one Modbus transaction)
            ident = await tr.drive.heartbeat_identify()
            tr.last_heartbeat = t
            await self._check_reboot(tr, ident)

    async def _check_restart(self, tr: TrackerRuntime) -> None:
        """A drive its backend started again after a boot-up message (a CANopen reboot or NMT
        reset, whose uptime may not go back) is configured again at once."""
        if tr.drive.restarts != tr.restarts_seen:
            log.warning("%s: drive restarted after a reboot or reset: configuring it again", tr.cfg.name)
            self._event("drive_reboot", tracker=tr.cfg.name)
            tr.uptime_s = None
            await self._configure(tr, rebooted=True, connected=True)

    async def _check_reboot(self, tr: TrackerRuntime, ident: DriveIdentity | None) -> None:
        """A drive whose uptime went back has rebooted: it forgot its configuration (limits,
        stow angle, watchdog), so it is configured again before the next exchange."""
        if ident is None:
            return
        now = self.clock.monotonic()
        # the uptime it should show by now, had it not restarted since the last reading
        expected = None if tr.uptime_s is None else tr.uptime_s + (now - tr.uptime_at)
        before = tr.uptime_s
        tr.uptime_s, tr.uptime_at = ident.uptime_s, now
        if expected is not None and before is not None and ident.uptime_s + 5.0 < expected:
            log.warning(
                "%s: drive rebooted (uptime %.0f s, was %.0f s): configuring it again",
                tr.cfg.name,
                ident.uptime_s,
                before,
            )
            self._event("drive_reboot", tracker=tr.cfg.name)
            tr.uptime_s = None
            await self._configure(tr, rebooted=True)
