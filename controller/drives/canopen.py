"""CANopen CiA 402 drive link (``canopen``), on python-can through the canopen library.

One heliotrack drive is one CANopen node per axis (axis ``k`` at ``node_id + k``; see
``docs/canopen.md``).  Each axis is a canopen ``BaseNode402``: the library runs the power
state machine, this module adds the heliotrack parts:

- connect: identification by SDO (0x2000 magic, 0x2001 protocol, 0x2002 axis count, 0x2020
  axis index), PDO configuration read by SDO (or taken from the EDS), producer heartbeat,
  NMT start, profile position mode, OPERATION ENABLED;
- targets: RPDO1 (controlword + 0x607A) with the new-set-point handshake (bit 4 up, wait for
  statusword bit 12, bit 4 down);
- state: the last TPDOs (statusword, position, heliotrack status/fault/mode, velocity,
  effective target), refused when older than ``stale_s`` or when the drive's heartbeat
  stopped (heartbeat consumer);
- heartbeat: this master produces heartbeats (COB-ID 0x700 + ``master_node_id``), which the
  drives consume (0x1016) and stow without.

The canopen library is synchronous and threaded: quick non-blocking operations (PDO
transmit, cached TPDO values) run in the event loop; SDO transfers and the blocking 402
helpers run in worker threads (``asyncio.to_thread``).
"""

from __future__ import annotations

import asyncio
import io
import logging
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import canopen
from canopen.objectdictionary import eds as eds_format
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from firmware_protocol import MAGIC, PROTOCOL_VERSION, Command, Fault, Mode, Status, register
from firmware_protocol.canopen import (
    AXIS_INDEX_OBJECT, CW_ENABLE_OPERATION, CW_NEW_SET_POINT, MASTER_NODE_ID, State402, Statusword, check_node_id, eds, mirror_index, state_from_statusword,
)
from firmware_protocol.codec import to_raw

from .base import AxisState, DriveCommError, DriveLink, DriveState, LinkStats, register_backend
from .links import CanopenLink, LinkConfig

log = logging.getLogger(__name__)

_TARGET = register("TARGET_ANGLE")
_ACTUAL = register("ACTUAL_ANGLE")
_VELOCITY = register("VELOCITY")
_LIMIT_MIN = register("SOFT_LIMIT_MIN")
_LIMIT_MAX = register("SOFT_LIMIT_MAX")
_STOW = register("STOW_ANGLE")
_IDX_STATUS = mirror_index(register("STATUS"))
_IDX_FAULT = mirror_index(register("FAULT_CODE"))
_IDX_MODE = mirror_index(register("MODE"))
_IDX_EFFECTIVE_TARGET = mirror_index(_TARGET)
_IDX_COMMAND = mirror_index(register("COMMAND"))
_IDX_MAGIC, _IDX_PROTOCOL, _IDX_AXES = (mirror_index(register(n)) for n in
                                         ("MAGIC", "PROTOCOL_VERSION", "AXIS_COUNT"))
_HEARTBEAT_MIN_INTERVAL_S = 0.05    # many drives on one network share one master heartbeat
_SDO_ERRORS = (SdoAbortedError, SdoCommunicationError, canopen.nmt.NmtError, OSError,
               RuntimeError)


def _load_od(eds_path: str | Path | None, node_id: int) -> canopen.ObjectDictionary:
    if eds_path is None:
        return eds_format.import_eds(io.StringIO(eds()), node_id)
    return canopen.import_od(str(eds_path), node_id)


class _SharedNetwork:
    """One canopen Network per (interface, channel), shared by every drive on that bus.

    A USB-CAN adapter (slcan) can be opened once; a virtual channel could be opened many
    times, but one network per bus keeps one notifier thread instead of hundreds.
    """

    _open: dict[tuple[str, str], "_SharedNetwork"] = {}
    _lock = threading.Lock()

    def __init__(self, interface: str, channel: str, bus_kwargs: dict):
        self.key = (interface, channel)
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = 0.1   # closing waits for one notifier cycle
        self.network.connect(interface=interface, channel=channel, **bus_kwargs)
        self.users = 0

    @classmethod
    def acquire(cls, interface: str, channel: str, bus_kwargs: dict) -> "_SharedNetwork":
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
                self._open.pop(self.key, None)
                self.network.disconnect()


_last_master_beat: dict[int, float] = {}


class _Axis:
    """Per-axis bookkeeping: the 402 node, TPDO reception times, heartbeat time."""

    def __init__(self, node: canopen.BaseNode402):
        self.node = node
        self.tpdo_time: dict[int, float] = {}      # TPDO number -> monotonic reception
        self.heartbeat_time: float | None = None

    @property
    def statusword(self) -> int:
        return int(self.node.tpdo_values.get(0x6041, 0))

    @property
    def state(self) -> State402 | None:
        return state_from_statusword(self.statusword)


class CanopenDrive(DriveLink):
    """A drive whose axes are CiA 402 nodes ``node_id``, ``node_id + 1``.

    Parameters
    ----------
    node_id : int
        Node id of axis 0 (1..126).
    channel : str, optional
        python-can channel (``/dev/ttyACM0`` for slcan, ``can0`` for socketcan, a name for
        ``virtual``).  Not needed when ``network`` is given.
    interface : str
        python-can interface: ``virtual``, ``slcan`` or ``socketcan``.
    bitrate : int, optional
        CAN bit rate, bit/s (slcan/socketcan).
    eds : path, optional
        EDS to load; default: the generated ``firmware_protocol`` dictionary.
    timeout_s : float
        SDO response timeout and set-point acknowledge timeout, s.
    retries : int
        Extra attempts of a failed SDO transfer or set-point handshake.
    network : canopen.Network, optional
        An already-connected network to share among many drives (not closed by us).
    master_node_id : int
        Node id this master's heartbeat is produced under (the drives consume it).
    producer_heartbeat_ms : int
        Heartbeat period asked of each drive node (0x1017), ms; 0 leaves it unchanged.
    stale_s : float, optional
        State older than this is refused, s (default: 3 heartbeat periods, at least 1 s).
    pdo_from_eds : bool
        Take the PDO mapping from the EDS instead of reading it by SDO (faster start-up of
        many drives; only for drives known to use the default mapping).
    label : str
        For error messages.
    """

    config_type = CanopenLink

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> "CanopenDrive":
        assert isinstance(link, CanopenLink)
        return cls(device_id, channel=link.channel, interface=link.interface,
                   bitrate=link.bitrate if link.interface != "virtual" else None,
                   timeout_s=link.timeout_s, retries=link.retries)

    def __init__(self, node_id: int, *, channel: str | None = None, interface: str = "virtual",
                 bitrate: int | None = None, eds: str | Path | None = None,
                 timeout_s: float = 0.5, retries: int = 2,
                 network: canopen.Network | None = None, master_node_id: int = MASTER_NODE_ID,
                 producer_heartbeat_ms: int = 1000, stale_s: float | None = None,
                 pdo_from_eds: bool = False, label: str = "", **bus_kwargs):
        try:
            check_node_id(node_id)
        except ValueError as exc:
            raise DriveCommError(str(exc)) from None
        if network is None and channel is None:
            raise ValueError("give either channel (and interface) or network")
        self.node_id = node_id
        self.channel, self.interface, self.bitrate = channel, interface, bitrate
        self.eds = eds
        self.timeout_s, self.retries = timeout_s, retries
        self.master_node_id = master_node_id
        self.producer_heartbeat_ms = producer_heartbeat_ms
        self.stale_s = stale_s if stale_s is not None else max(1.0, 3 * producer_heartbeat_ms / 1000)
        self.pdo_from_eds = pdo_from_eds
        self.label = label or f"{interface}:{channel or 'shared'} node {node_id}"
        self.bus_kwargs = dict(bus_kwargs)
        if interface == "slcan":
            self.bus_kwargs.setdefault("sleep_after_open", 0)
        if bitrate is not None:
            self.bus_kwargs["bitrate"] = bitrate
        self.network = network
        self._shared: _SharedNetwork | None = None
        self.axes: list[_Axis] = []
        self._added: list[canopen.BaseNode402] = []
        self.axis_count = 0
        self.stats = LinkStats()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tpdo_event: asyncio.Event | None = None

    # -- helpers ------------------------------------------------------------------------
    async def _sdo(self, what: str, fn, *args):
        """Run a blocking SDO operation in a thread, with retries."""
        last: BaseException | None = None
        for attempt in range(self.retries + 1):
            t0 = time.perf_counter()
            self.stats.transactions += 1
            try:
                result = await asyncio.to_thread(fn, *args)
            except SdoAbortedError as exc:   # the drive refused: retrying will not help
                self.stats.errors += 1
                raise DriveCommError(f"{self.label}: {what} refused by the drive: {exc}") from None
            except _SDO_ERRORS as exc:
                last = exc
                self.stats.errors += 1
                if attempt < self.retries:
                    self.stats.retries += 1
                continue
            self.stats.latencies_s.append(time.perf_counter() - t0)
            return result
        raise DriveCommError(f"{self.label}: {what} failed after {self.retries + 1} attempt(s): {last}")

    def _on_tpdo(self, axis: _Axis, number: int):
        def callback(_pdo) -> None:   # canopen's receive thread
            axis.tpdo_time[number] = time.monotonic()
            loop, event = self._loop, self._tpdo_event
            if loop is not None and event is not None and not loop.is_closed():
                loop.call_soon_threadsafe(event.set)
        return callback

    async def _wait(self, predicate, timeout: float) -> bool:
        """Wait until ``predicate()`` holds, re-checking whenever a TPDO arrives."""
        assert self._tpdo_event is not None
        deadline = time.monotonic() + timeout
        while True:
            self._tpdo_event.clear()
            if predicate():
                return True
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            try:
                await asyncio.wait_for(self._tpdo_event.wait(), left)
            except asyncio.TimeoutError:
                return predicate()

    # -- connection ---------------------------------------------------------------------
    async def connect(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._tpdo_event = asyncio.Event()
        if self.network is None:
            try:
                self._shared = await asyncio.to_thread(
                    _SharedNetwork.acquire, self.interface, self.channel, self.bus_kwargs)
            except Exception as exc:   # python-can raises many kinds on a bad channel
                raise DriveCommError(f"{self.label}: cannot open the CAN bus: {exc}") from None
            self.network = self._shared.network
        try:
            first = self._add_node(self.node_id)
            magic = await self._sdo("identification read", lambda: first.sdo[_IDX_MAGIC].raw)
            if magic != MAGIC:
                raise DriveCommError(f"{self.label}: not a heliotrack drive (0x{_IDX_MAGIC:04X} = {magic:#06x})")
            version = await self._sdo("identification read", lambda: first.sdo[_IDX_PROTOCOL].raw)
            if version >> 8 != PROTOCOL_VERSION >> 8:
                raise DriveCommError(f"{self.label}: protocol {version >> 8}.x, expected {PROTOCOL_VERSION >> 8}.x")
            count = await self._sdo("identification read", lambda: first.sdo[_IDX_AXES].raw)
            if not 1 <= count <= 2:
                raise DriveCommError(f"{self.label}: implausible axis count {count}")
            check_node_id(self.node_id, count)
            self.axes = [_Axis(first)]
            for k in range(1, count):
                self.axes.append(_Axis(self._add_node(self.node_id + k)))
            for k, axis in enumerate(self.axes):
                index = await self._sdo("axis index read",
                                        lambda n=axis.node: n.sdo[AXIS_INDEX_OBJECT].raw)
                if index != k:
                    raise DriveCommError(f"{self.label}: node {axis.node.id} is axis {index}, expected {k}")
                await self._start_axis(axis)
            self.axis_count = count
        except BaseException:
            await self.close()
            raise

    def _add_node(self, node_id: int) -> canopen.BaseNode402:
        if node_id in self.network.nodes:
            raise DriveCommError(f"{self.label}: node {node_id} is already in use on this network")
        node = canopen.BaseNode402(node_id, _load_od(self.eds, node_id))
        node.sdo.RESPONSE_TIMEOUT = self.timeout_s
        self.network.add_node(node)
        self._added.append(node)
        return node

    async def _start_axis(self, axis: _Axis) -> None:
        node = axis.node

        def read_pdos() -> None:
            node.tpdo.read(from_od=self.pdo_from_eds)
            node.rpdo.read(from_od=self.pdo_from_eds)

        await self._sdo("PDO configuration read", read_pdos)
        node.setup_402_state_machine(read_pdos=False)
        for number, tpdo in node.tpdo.items():
            if tpdo.enabled:
                tpdo.add_callback(self._on_tpdo(axis, number))
        node.nmt.add_heartbeat_callback(lambda _state, a=axis: setattr(a, "heartbeat_time", time.monotonic()))
        if self.producer_heartbeat_ms:
            await self._sdo("producer heartbeat write",
                            lambda: setattr(node.sdo[0x1017], "raw", self.producer_heartbeat_ms))
        node.nmt.state = "OPERATIONAL"     # NMT start: PDOs flow from now on
        # Every TPDO goes out once after NMT start; waiting for them means the state is
        # known before the 402 helper starts switching (a drive that stays silent fails
        # in _enable with a clear timeout).
        await self._wait(lambda: all(n in axis.tpdo_time for n, p in node.tpdo.items()
                                     if p.enabled), self.timeout_s * 2)
        actual = await self._sdo("position read", lambda: node.sdo[0x6064].raw)
        if 0x607A in node.rpdo_pointers:
            node.rpdo_pointers[0x607A].raw = actual   # no jump if a set-point slips through
        await self._enable(axis)

    async def _enable(self, axis: _Axis) -> None:
        """Profile position mode and OPERATION ENABLED (the 402 helper's blocking calls)."""
        node = axis.node

        def enable() -> None:
            node.op_mode = "PROFILED POSITION"
            node.state = "OPERATION ENABLED"

        try:
            await self._sdo("enable operation", enable)
        except DriveCommError:
            if axis.state == State402.FAULT:
                # A faulted drive still connects: read_state reports the fault and
                # command(CLEAR_FAULT) recovers it.
                log.warning("%s: node %d is in FAULT", self.label, node.id)
                return
            raise

    async def close(self) -> None:
        """Forget the drive's nodes (the drives keep their state: a tracker holds)."""
        for node in self._added:   # only the nodes this drive added: the network is shared
            for tpdo in node.tpdo.values():
                if tpdo.enabled and tpdo.cob_id:
                    try:
                        self.network.unsubscribe(tpdo.cob_id, tpdo.on_message)
                    except (KeyError, ValueError):
                        pass
            node.remove_network()
            self.network.nodes.pop(node.id, None)
        self._added = []
        self.axes = []
        self.axis_count = 0
        if self._shared is not None:
            self._shared.release()
            self._shared = None
            self.network = None

    # -- state --------------------------------------------------------------------------
    def _fresh(self, axis: _Axis, now: float) -> None:
        node = axis.node
        if axis.heartbeat_time is not None and \
                now - axis.heartbeat_time > 3 * self.producer_heartbeat_ms / 1000 > 0:
            raise DriveCommError(f"{self.label}: heartbeat of node {node.id} lost")
        if node.nmt.state not in ("OPERATIONAL", "INITIALISING") and axis.heartbeat_time:
            raise DriveCommError(f"{self.label}: node {node.id} left OPERATIONAL "
                                 f"(NMT {node.nmt.state}); reconnect")
        for number, tpdo in node.tpdo.items():
            if not tpdo.enabled:
                continue
            t = axis.tpdo_time.get(number)
            if t is None or now - t > self.stale_s:
                raise DriveCommError(f"{self.label}: no TPDO{number} from node {node.id} "
                                     f"for {self.stale_s:g} s")

    def _axis_state(self, axis: _Axis) -> AxisState:
        v = axis.node.tpdo_values
        try:
            return AxisState(
                actual_deg=v[0x6064] * _ACTUAL.scale,
                target_deg=v[_IDX_EFFECTIVE_TARGET] * _TARGET.scale,
                velocity_dps=v[0x606C] * _VELOCITY.scale,
                status=Status(int(v[_IDX_STATUS])),
                fault=Fault(int(v[_IDX_FAULT])),
                mode=Mode(int(v[_IDX_MODE])))
        except KeyError as exc:
            raise DriveCommError(f"{self.label}: node {axis.node.id} does not map "
                                 f"0x{exc.args[0]:04X} in a TPDO") from None
        except ValueError as exc:   # an unknown fault or mode code on the wire
            raise DriveCommError(f"{self.label}: implausible state from node {axis.node.id}: {exc}") from None

    async def read_state(self) -> DriveState:
        if not self.axes:
            raise DriveCommError(f"{self.label}: not connected")
        now = time.monotonic()
        axes = []
        for axis in self.axes:
            self._fresh(axis, now)
            axes.append(self._axis_state(axis))
        dev = Status(0)
        for a in axes:
            dev |= a.status
        return DriveState(self.axis_count, tuple(axes), dev)

    # -- targets ------------------------------------------------------------------------
    async def write_targets(self, angles_deg: Sequence[float]) -> None:
        if len(angles_deg) != self.axis_count:
            raise ValueError(f"{self.label}: {len(angles_deg)} targets for {self.axis_count} axes")
        # Encode everything first: a bad angle (NaN, out of range) sends nothing at all.
        raws = [to_raw(_TARGET, angle) for angle in angles_deg]
        for k, (axis, raw) in enumerate(zip(self.axes, raws)):
            state = axis.state
            if state == State402.FAULT:
                continue   # read_state shows the fault; command(CLEAR_FAULT) recovers
            if state != State402.OPERATION_ENABLED:
                raise DriveCommError(f"{self.label}: axis {k} (node {axis.node.id}) is "
                                     f"{state.name if state else 'in an unknown state'}, not "
                                     "OPERATION ENABLED; not re-enabled automatically")
            await self._set_point(k, axis, raw)

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        """Write targets, then read the state once it reflects them (like Modbus FC23).

        The effective target travels back in a TPDO; wait (at most ``timeout_s``) until
        each axis's TPDO shows the requested value or a TPDO mapping it has arrived since
        the write (the drive may have clamped the value).
        """
        await self.write_targets(angles_deg)
        t_written = time.monotonic()
        raws = [to_raw(_TARGET, a) for a in angles_deg]

        def reflected() -> bool:
            for axis, raw in zip(self.axes, raws):
                if axis.node.tpdo_values.get(_IDX_EFFECTIVE_TARGET) == raw:
                    continue
                numbers = [n for n, t in axis.node.tpdo.items() if t.enabled and
                           any(v.index == _IDX_EFFECTIVE_TARGET for v in t.map)]
                if not all(axis.tpdo_time.get(n, 0.0) > t_written for n in numbers):
                    return False
            return True

        await self._wait(reflected, self.timeout_s)
        return await self.read_state()

    async def _set_point(self, k: int, axis: _Axis, raw: int) -> None:
        node = axis.node
        ack = lambda: bool(axis.statusword & Statusword.SET_POINT_ACK)  # noqa: E731
        for attempt in range(self.retries + 1):
            t0 = time.perf_counter()
            self.stats.transactions += 1
            # Handshake: the previous set-point's acknowledge must be down first.
            if ack():
                self._controlword(node, CW_ENABLE_OPERATION)
                await self._wait(lambda: not ack(), self.timeout_s)
            if 0x607A in node.rpdo_pointers:
                node.rpdo_pointers[0x607A].raw = raw
                target_pdo = node.rpdo_pointers[0x607A].pdo_parent
                if 0x6040 not in node.rpdo_pointers or \
                        node.rpdo_pointers[0x6040].pdo_parent is not target_pdo:
                    target_pdo.transmit()
            else:
                await self._sdo("target write", lambda: setattr(node.sdo[0x607A], "raw", raw))
            self._controlword(node, CW_NEW_SET_POINT)
            taken = await self._wait(ack, self.timeout_s)
            self._controlword(node, CW_ENABLE_OPERATION)
            if taken:
                self.stats.latencies_s.append(time.perf_counter() - t0)
                return
            self.stats.errors += 1
            if attempt < self.retries:
                self.stats.retries += 1
        raise DriveCommError(f"{self.label}: axis {k} did not acknowledge the set-point "
                             f"within {self.timeout_s:g} s ({self.retries + 1} attempt(s))")

    @staticmethod
    def _controlword(node: canopen.BaseNode402, cw: int) -> None:
        node.controlword = int(cw)   # RPDO transmit (non-blocking) or SDO fallback

    # -- heartbeat, commands, configuration -------------------------------------------------
    async def heartbeat(self) -> None:
        if self.network is None:
            raise DriveCommError(f"{self.label}: not connected")
        now = time.monotonic()
        key = id(self.network)
        if now - _last_master_beat.get(key, -1e9) < _HEARTBEAT_MIN_INTERVAL_S:
            return
        _last_master_beat[key] = now
        try:
            self.network.send_message(0x700 + self.master_node_id, bytes([0x05]))
        except Exception as exc:   # python-can CanError, OSError on a pulled adapter
            self.stats.errors += 1
            raise DriveCommError(f"{self.label}: heartbeat not sent: {exc}") from None
        self.stats.transactions += 1

    async def command(self, cmd: Command) -> None:
        if not self.axes:
            raise DriveCommError(f"{self.label}: not connected")
        first = self.axes[0].node
        await self._sdo(f"command {cmd.name}",
                        lambda: setattr(first.sdo[_IDX_COMMAND], "raw", int(cmd)))
        if cmd in (Command.CLEAR_FAULT, Command.RESUME):
            # An explicit operator command: bring every axis back to OPERATION ENABLED
            # (from FAULT through a fault-reset edge, which the 402 helper sends).
            for axis in self.axes:
                if axis.state != State402.OPERATION_ENABLED:
                    if axis.state == State402.FAULT:
                        self._controlword(axis.node, 0)   # bit 7 low, so the next is an edge
                    await self._sdo("re-enable", lambda n=axis.node: setattr(n, "state", "OPERATION ENABLED"))

    async def configure(self, *, heartbeat_timeout_s=None, soft_limits=None, stow_angles=None) -> None:
        if not self.axes:
            raise DriveCommError(f"{self.label}: not connected")
        if heartbeat_timeout_s is not None:
            ms = round(heartbeat_timeout_s * 1000)
            if not 0 <= ms <= 0xFFFF:
                raise ValueError(f"heartbeat timeout {heartbeat_timeout_s} s outside 0..65.535 s")
            value = (self.master_node_id << 16) | ms
            for axis in self.axes:
                await self._sdo("consumer heartbeat write",
                                lambda n=axis.node: setattr(n.sdo[0x1016][1], "raw", value))
        for k, (lo, hi) in enumerate(soft_limits or ()):
            node = self.axes[k].node
            lo_raw, hi_raw = to_raw(_LIMIT_MIN, lo), to_raw(_LIMIT_MAX, hi)
            if lo_raw > hi_raw:
                raise ValueError(f"soft limits of axis {k}: min {lo} > max {hi}")
            await self._sdo("soft limit write", lambda n=node: setattr(n.sdo[0x607D][1], "raw", lo_raw))
            await self._sdo("soft limit write", lambda n=node: setattr(n.sdo[0x607D][2], "raw", hi_raw))
        for k, angle in enumerate(stow_angles or ()):
            node = self.axes[k].node
            raw = to_raw(_STOW, angle)
            await self._sdo("stow angle write",
                            lambda n=node: setattr(n.sdo[mirror_index(_STOW)], "raw", raw))


def _factory(node_id: int, **kwargs) -> CanopenDrive:
    return CanopenDrive(node_id, **kwargs)


register_backend("canopen", _factory)

__all__ = ["CanopenDrive"]
