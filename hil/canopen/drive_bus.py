"""What the axis nodes of one emulated drive share (one firmware, one watchdog)."""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

from firmware_protocol import register
from firmware_protocol.canopen import MASTER_NODE_ID
from hil.drive.firmware import DriveFirmware

if TYPE_CHECKING:
    from .node import AxisNode


class DriveBus:
    """What the axis nodes of one drive share: the firmware, a lock, a heartbeat counter,
    and the node whose heartbeat feeds the watchdog.

    Parameters
    ----------
    firmware : DriveFirmware
        The drive's firmware (its ``now`` is the physics clock).
    """

    def __init__(self, firmware: DriveFirmware):
        self.fw = firmware
        self.lock = threading.RLock()
        self._beat = 0
        #: Node id of the heartbeat producer the watchdog consumes (0x1016:1 of any axis).
        self.producer = MASTER_NODE_ID
        self.nodes: list[AxisNode] = []

    @property
    def node_ids(self) -> list[int]:
        return [n.id for n in self.nodes]

    def beat(self) -> None:
        """A heartbeat of the master arrived: feed the firmware watchdog."""
        self._beat = (self._beat + 1) & 0xFFFF
        self.fw.write(register("HEARTBEAT").address(), [self._beat])

    def set_producer(self, producer: int) -> None:
        """Consume the heartbeat of ``producer`` on every axis node (the watchdog is the
        drive's: 0x1016 written on one axis sets it for all)."""
        self.producer = producer
        for node in self.nodes:
            node.listen_to(producer)
