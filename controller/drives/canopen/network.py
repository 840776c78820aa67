"""The CAN side every drive on one bus shares: the canopen ``Network`` and the master's
heartbeat."""

from __future__ import annotations

import asyncio
import threading
from typing import Any, ClassVar

import canopen


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
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.1  # closing waits for one notifier cycle
        self.network.connect(interface=interface, channel=channel, **bus_kwargs)
        self.users = 0

    @classmethod
    def acquire(cls, interface: str, channel: str, bus_kwargs: dict[str, Any]) -> SharedNetwork:
        """The network of this bus, connected now if it is new (blocking: call in a thread).

        Raises whatever python-can raises for a bus it cannot open.
        """
        with cls._lock:
            shared = cls._open.get((interface, channel))
            if shared is None:
                shared = cls._open[(interface, channel)] = cls(interface, channel, bus_kwargs)
            shared.users += 1
            return shared

    def release(self) -> None:
        with self._lock:
            self.users -= 1
            if self.users <= 0:
                if self._open.get(self.key) is self:
                    del self._open[self.key]
                self.network.disconnect()


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
