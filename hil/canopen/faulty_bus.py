"""CAN faults between the emulated drives and the bus: frames lost, error-passive, bus-off.

:class:`FaultyBus` wraps the emulator's python-can bus; every frame the drives send or
receive passes :meth:`CanFaults.drop` first:

- ``can_frame_lost``: each frame is lost with a small probability (counted and logged
  with the node id it belonged to);
- ``error_passive``: while on, frames are lost intermittently (a node fighting bit errors
  retransmits late or not at all);
- ``bus_off``: while on, nothing passes either way (the drives' controllers have left the
  bus; they come back when it ends).

The hook sits in the bus layer, under the canopen nodes, so the nodes' own protocol code
is untouched.
"""

from __future__ import annotations

import random
import threading
from collections import Counter, deque
from typing import Any

import can

from ..wire_faults import WireEvent


class CanFaults:
    """What happens to the frames of one emulated CAN network.

    Parameters
    ----------
    frame_loss : float
        Probability that any one frame is lost, in [0, 1].
    seed : int
    error_passive_loss : float
        Probability of loss of each frame while error-passive.
    """

    def __init__(self, frame_loss: float = 0.0, seed: int = 0, error_passive_loss: float = 0.3):
        if not 0.0 <= frame_loss <= 1.0 or not 0.0 <= error_passive_loss <= 1.0:
            raise ValueError("CAN loss probabilities must be in [0, 1]")
        self.frame_loss = frame_loss
        self.error_passive_loss = error_passive_loss
        #: None, "error_passive" or "bus_off" (set by the fault scheduler).
        self.state: str | None = None
        self.rng = random.Random(seed)
        self.injected: Counter[str] = Counter()
        self.events: deque[WireEvent] = deque()
        self._lock = threading.Lock()

    def drop(self, msg: can.Message) -> bool:
        """True when ``msg`` is lost."""
        if self.state == "bus_off":
            return True
        with self._lock:
            if self.state == "error_passive" and self.rng.random() < self.error_passive_loss:
                return True
            if self.frame_loss and self.rng.random() < self.frame_loss:
                self.injected["can_frame_lost"] += 1
                self.events.append(WireEvent("can_frame_lost", msg.arbitration_id & 0x7F))
                return True
        return False

    def drain(self) -> list[WireEvent]:
        out = []
        while self.events:
            out.append(self.events.popleft())
        return out


class FaultyBus(can.BusABC):
    """A python-can bus whose frames (both ways) pass :meth:`CanFaults.drop` first."""

    def __init__(self, inner: can.BusABC, faults: CanFaults, **kwargs: Any):
        self.inner = inner
        self.faults = faults
        self.channel_info = f"faulty {inner.channel_info}"
        super().__init__(channel=str(getattr(inner, "channel", "faulty")), **kwargs)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not self.faults.drop(msg):
            self.inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self.inner.recv(timeout)
        if msg is not None and self.faults.drop(msg):
            return None, False
        return msg, False

    def shutdown(self) -> None:
        self.inner.shutdown()
        super().shutdown()
