"""The CAN side every drive on one bus shares: the canopen ``Network`` and the master's
heartbeat."""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import logging
import os
import select
import struct
import threading
import time
from typing import Any, ClassVar

import can
import canopen

log = logging.getLogger(__name__)

#: What a bus's reader raises for one malformed frame (slcan: a line that is not hex).
_FRAME_ERRORS = (ValueError, IndexError, struct.error)


class TolerantBus(can.BusABC):
    """A python-can bus whose malformed received frames are dropped and counted.

    python-can's notifier thread stops for good at the first exception its bus raises: one
    garbled slcan line (noise on the USB serial link, a second program on the adapter)
    had left every drive on the bus without state until the controller restarted.  A
    bus that cannot be read at all (an adapter unplugged) still raises: that is the
    link's failure, handled by reconnecting.
    """

    def __init__(self, inner: can.BusABC, **kwargs: Any):
        self.inner = inner
        self.dropped = 0
        self._said = -float("inf")
        self.channel_info = inner.channel_info
        super().__init__(channel=str(getattr(inner, "channel", inner.channel_info)), **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            return self.inner.recv(timeout), False
        except _FRAME_ERRORS as exc:
            self.dropped += 1
            if time.monotonic() - self._said >= 60.0:  # at most a line a minute
                self._said = time.monotonic()
                log.warning(
                    "%s: a malformed frame was dropped (%s; %d so far)", self.channel_info, exc, self.dropped
                )
            return None, False

    def shutdown(self) -> None:
        try:
            self.inner.shutdown()
        finally:
            # slcan's shutdown writes its close command first: on an adapter unplugged that
            # raises, and the port stayed open, holding the vanished device's name (the
            # adapter plugged back came up as /dev/ttyACM1, and the link never found it)
            port = getattr(self.inner, "serialPortOrig", None)
            if port is not None:
                with contextlib.suppress(Exception):
                    port.close()
            super().shutdown()


class SharedNetwork:
    """One canopen Network per (interface, channel), shared by every drive on that bus.

    A USB-CAN adapter (slcan) can be opened once; a virtual channel could be opened many
    times, but one network per bus keeps one notifier thread instead of hundreds.  The bus
    closes when its last drive releases it.
    """

    _open: ClassVar[dict[tuple[str, str], SharedNetwork]] = {}
    _lock: ClassVar[threading.Lock] = threading.Lock()

    def __init__(self, interface: str, channel: str, bus_kwargs: dict[str, Any]):
        self.key = (interface, channel)
        self._lock_fd = lock_serial_adapter(interface, channel)
        try:
            self.bus = TolerantBus(can.Bus(interface=interface, channel=channel, **bus_kwargs))
        except BaseException:
            self._unlock()
            raise
        self.network = canopen.Network(self.bus)
        self.network.NOTIFIER_CYCLE = 0.1  # closing waits for one notifier cycle
        self.network.connect()  # the notifier, on the bus given
        self.users = 0

    @classmethod
    def acquire(cls, interface: str, channel: str, bus_kwargs: dict[str, Any]) -> SharedNetwork:
        """The network of this bus, connected now if it is new (blocking: call in a thread).

        Raises whatever python-can raises for a bus it cannot open.
        """
        with cls._lock:
            shared = cls._open.get((interface, channel))
            if shared is not None and shared.dead:
                # its reception stopped for good (an adapter unplugged, a pty gone): a new
                # network; the drives still on the old one get it when they reconnect
                del cls._open[(interface, channel)]
                shared._unlock()  # the new network takes the adapter's lock
                shared = None
            if shared is None:
                shared = cls._open[(interface, channel)] = cls(interface, channel, bus_kwargs)
            shared.users += 1
            return shared

    @property
    def dead(self) -> bool:
        """Nothing will be heard on this bus again: python-can's receive thread stopped on an
        error, or the serial adapter's port has hung up (unplugged; a pty whose other end
        closed).  The hang-up is asked of the port itself: the receive thread notices it
        only at its next read, and a network handed out in between, for a new adapter that
        came up under the old one's name (a full suite reuses pty names), had failed its
        first SDO with "device reports readiness to read but returned no data"."""
        notifier = self.network.notifier
        if notifier is not None and notifier.exception is not None:
            return True
        port = getattr(self.bus.inner, "serialPortOrig", None)
        fd = getattr(port, "fd", None)
        if fd is None:
            return False
        poller = select.poll()
        poller.register(fd, select.POLLIN)
        try:
            events = poller.poll(0)
        except OSError:
            return True
        return any(ev & (select.POLLHUP | select.POLLERR | select.POLLNVAL) for _, ev in events)

    def release(self) -> None:
        with self._lock:
            self.users -= 1
            if self.users <= 0:
                if self._open.get(self.key) is self:
                    del self._open[self.key]
                try:
                    self.network.disconnect()
                except Exception as exc:  # noqa: BLE001 - a dead bus raises its old error on the way out
                    log.debug("%s:%s: closed with %s", *self.key, exc)
                    with contextlib.suppress(Exception):  # closed even if the network's close stopped early
                        self.bus.shutdown()
                self._unlock()

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)
            self._lock_fd = None


def lock_serial_adapter(interface: str, channel: str) -> int | None:
    """Hold a serial-line CAN adapter (slcan: ``/dev/ttyACM0``, ``/dev/serial/by-id/...``,
    optionally ``@baud``) exclusively, as pyserial's ``exclusive`` does for a Modbus port:
    the file descriptor holding the lock, or None for another interface or a port that
    does not open (python-can then says why).

    python-can opens an slcan port without a lock, so ``heliotrack check`` beside a
    running ``run`` opened the same adapter: each took the other's bytes, and the
    running controller's reception stopped with a traceback, its CAN rows lost for a
    minute, while ``check`` called them ok.

    Raises
    ------
    can.CanInitializationError
        Another program holds the port.
    """
    if interface != "slcan" or "://" in channel:
        return None
    path = channel.split("@", 1)[0]
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise can.CanInitializationError(
            f"{path}: in use by another program (is heliotrack run active?)"
        ) from None
    return fd


#: Networks whose master heartbeat went out in the current event-loop iteration.
_beaten: set[int] = set()


def send_master_heartbeat(network: canopen.Network, master_node_id: int) -> bool:
    """Send the master's heartbeat (state OPERATIONAL) on ``network``, once however many of
    its drives ask in the same event-loop iteration; True if a frame went out.

    Every drive on a bus consumes the same master heartbeat, so the rows of one control
    cycle (whose exchanges start together) share one frame.  The merge is per loop
    iteration rather than per time window, so it holds on a simulated clock too, where a
    whole cycle can take less wall time than any window.
    """
    key = id(network)
    if key in _beaten:
        return False
    network.send_message(0x700 + master_node_id, bytes([0x05]))
    _beaten.add(key)
    asyncio.get_running_loop().call_soon(_beaten.discard, key)
    return True
