"""Emulated CANopen drives on one CAN network, serviced by one thread.

:class:`CanopenDriveEmulator` turns a :class:`~hil.drive.firmware.DriveFirmware` into one
CANopen node per axis.  :class:`CanopenNetworkEmulator` owns the canopen ``Network`` (a
python-can bus: ``virtual`` in-process, anything python-can opens otherwise) and services
every drive on it from a single thread, so a hundred drives cost one thread, not a
hundred.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Self

import can
import canopen

from firmware_protocol.canopen import axis_node_id, check_node_id
from hil.drive.firmware import DriveFirmware
from hil.errors import HilError

from .node import AxisNode, DriveBus

log = logging.getLogger(__name__)


class SafeNetwork(canopen.Network):
    """A canopen Network whose receive path survives a failing callback.

    The library's callbacks unpack frames without checking their length (an NMT command
    with one data byte raises ``struct.error``); an exception in the notifier thread would
    stop all reception, so it is logged and the frame is dropped instead.
    """

    #: Seconds per notifier iteration: closing the network waits for one of them.
    NOTIFIER_CYCLE = 0.1

    def notify(self, can_id: int, data: bytearray, timestamp: float) -> None:
        for callback in list(self.subscribers.get(can_id, ())):
            try:
                callback(can_id, data, timestamp)
            except Exception as exc:  # noqa: BLE001 - bad wire data must not kill the bus
                log.warning("frame 0x%03X %s dropped: %s", can_id, bytes(data).hex(), exc)
        self.scanner.on_message_received(can_id)


class CanopenDriveEmulator:
    """One emulated drive: axis ``k`` answers as node ``node_id + k``.

    Parameters
    ----------
    firmware : DriveFirmware
    node_id : int
        Node id of axis 0 (1..126, and ``node_id + axes - 1 <= 126``).
    wall : callable
        Monotonic seconds for bus timing.
    """

    def __init__(self, firmware: DriveFirmware, node_id: int, wall: Callable[[], float] = time.monotonic):
        n_axes = len(firmware.axes)
        try:
            check_node_id(node_id, n_axes)
        except ValueError as exc:
            raise HilError(str(exc)) from None
        self.firmware = firmware
        self.bus = DriveBus(firmware)
        self.nodes = [AxisNode(self.bus, k, axis_node_id(node_id, k), wall) for k in range(n_axes)]

    @property
    def node_ids(self) -> list[int]:
        return [n.id for n in self.nodes]

    def attach(self, network: canopen.Network) -> None:
        for n in self.nodes:
            n.attach(network)

    def detach(self) -> None:
        for n in self.nodes:
            n.detach()

    def service(self) -> None:
        for n in self.nodes:
            n.service()


class CanopenNetworkEmulator:
    """Drives on one CAN bus, serviced every ``period_s`` by a daemon thread.

    Parameters
    ----------
    channel : str
        python-can channel (for ``virtual``: any name shared with the master).
    interface : str
        python-can interface; ``virtual`` for in-process tests and benchmarks.
    bus : can.BusABC, optional
        An already-open bus to use instead of opening ``channel``.
    period_s : float
        Service period, s: bounds how late an event-driven TPDO (motion, a fault, the
        watchdog) goes out.  Writes from the master are answered at once, not on this
        period.  Servicing costs about 0.1 ms per node, so 100 nodes at 0.05 s take ~20 %
        of a core.
    bus_kwargs
        Passed to ``can.Bus``.
    """

    def __init__(
        self,
        channel: str = "heliotrack",
        interface: str = "virtual",
        *,
        bus: can.BusABC | None = None,
        period_s: float = 0.05,
        **bus_kwargs,
    ):
        self.network = SafeNetwork(bus)
        if bus is None:
            self.network.connect(interface=interface, channel=channel, **bus_kwargs)
        else:
            self.network.notifier = can.Notifier(bus, self.network.listeners, self.network.NOTIFIER_CYCLE)
        self.period_s = period_s
        self.drives: list[CanopenDriveEmulator] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.service_errors = 0

    def add_drive(
        self, firmware: DriveFirmware, node_id: int, wall: Callable[[], float] = time.monotonic
    ) -> CanopenDriveEmulator:
        """Put a drive on the bus (its nodes send their boot-up messages now)."""
        used = {i for d in self.drives for i in d.node_ids}
        drive = CanopenDriveEmulator(firmware, node_id, wall)
        clash = used.intersection(drive.node_ids)
        if clash:
            raise HilError(f"node id(s) {sorted(clash)} already used on this bus")
        drive.attach(self.network)
        with self._lock:
            self.drives.append(drive)
        return drive

    def remove_drive(self, drive: CanopenDriveEmulator) -> None:
        """Take a drive off the bus (as if its cable were pulled)."""
        with self._lock:
            self.drives.remove(drive)
        drive.detach()

    def service(self) -> None:
        """Service every drive once (the thread calls this; tests may call it directly)."""
        with self._lock:
            drives = list(self.drives)
        for d in drives:
            try:
                d.service()
            except Exception:  # one broken drive must not stop the others
                self.service_errors += 1
                log.exception("drive %s: service failed", d.node_ids)

    def start(self) -> Self:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="canopen-emulator", daemon=True)
        self._thread.start()
        return self

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            self.service()
            next_t += self.period_s
            delay = next_t - time.monotonic()
            if delay < 0:  # overloaded: do not try to catch up in a burst
                next_t = time.monotonic()
                delay = 0
            self._stop.wait(delay)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        for d in list(self.drives):
            d.detach()
        self.drives.clear()
        self.network.disconnect()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
