"""The CANopen CiA 402 drive (link kind ``canopen``), on python-can through canopen.

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
import contextlib
import logging
import time
from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import canopen
from canopen.sdo import SdoAbortedError, SdoCommunicationError

from firmware_protocol import Command, Status, register
from firmware_protocol.canopen import (
    AXIS_INDEX_OBJECT,
    MASTER_NODE_ID,
    State402,
    check_node_id,
    mirror_index,
)
from firmware_protocol.codec import to_raw

from ..base import (
    DriveCommError,
    DriveHeld,
    DriveIdentity,
    DriveLink,
    DriveState,
    LinkSettingsError,
    LinkStats,
)
from ..configuration import DriveConfiguration
from ..links import CanopenLink, LinkConfig
from ..retry import RetryPolicy
from .axis import Axis402, all_fresh, load_od, log_emcy
from .axis_control import SetPointNotAcknowledged, enable, reenable, set_point
from .configure import configure_drive, read_configuration
from .identity import check_new, identify
from .network import SharedNetwork, send_master_heartbeat

log = logging.getLogger(__name__)

_TARGET = register("TARGET_ANGLE")
_IDX_COMMAND = mirror_index(register("COMMAND"))
#: SDO failures worth another attempt; an abort is the drive's answer and final.  An answer
#: of the wrong size for the object's type does not decode (ObjectDictionaryError): garbled.
_SDO_RETRY_ON = (
    SdoCommunicationError,
    canopen.nmt.NmtError,
    canopen.objectdictionary.ObjectDictionaryError,
    OSError,
    RuntimeError,
)


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
    probe_policy = "sdo_policy"

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> CanopenDrive:
        """The drive whose axis 0 is node ``device_id`` on ``link``'s bus (shared with every
        other drive on it), not yet connected."""
        if not isinstance(link, CanopenLink):
            raise TypeError(f"{cls.__name__} needs a CanopenLink, got {type(link).__name__}")
        if link.is_hil:
            raise LinkSettingsError(
                f'link {link.name!r}: channel = "hil" names a bus that only '
                "`heliotrack simulate` provides; give the real one"
            )
        return cls(
            device_id,
            channel=link.channel,
            interface=link.interface,
            bitrate=link.bitrate if link.interface != "virtual" else None,
            timeout_s=link.timeout_s,
            retries=link.retries,
            pdo_from_eds=link.pdo_mapping == "eds",
            label=f"{link.name} ({link.interface}:{link.channel}) node {device_id}",
        )

    def __init__(
        self,
        node_id: int,
        *,
        channel: str | None = None,
        interface: str = "virtual",
        bitrate: int | None = None,
        eds: str | Path | None = None,
        timeout_s: float = 0.5,
        retries: int = 2,
        network: canopen.Network | None = None,
        master_node_id: int = MASTER_NODE_ID,
        producer_heartbeat_ms: int = 1000,
        stale_s: float | None = None,
        pdo_from_eds: bool = False,
        label: str = "",
        **bus_kwargs: Any,
    ):
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
        self.sdo_policy = RetryPolicy(retries, retry_on=_SDO_RETRY_ON, final=(SdoAbortedError,))
        self.set_point_policy = RetryPolicy(retries, retry_on=(SetPointNotAcknowledged,))
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
        self._shared: SharedNetwork | None = None
        self.axes: list[Axis402] = []
        self._added: list[canopen.BaseNode402] = []
        self.axis_count = 0
        self.stats = LinkStats()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tpdo_event: asyncio.Event | None = None
        #: After a failed transaction the TPDOs held may predate what the drive did while
        #: we could not hear it: a state needs TPDOs received after this (time.monotonic()).
        self._fresh_after = 0.0

    # -- helpers ------------------------------------------------------------------------
    @property
    def _net(self) -> canopen.Network:
        if self.network is None:
            raise DriveCommError(f"{self.label}: not connected")
        return self.network

    async def sdo(self, what: str, fn: Callable[[], Any]) -> Any:
        """Run a blocking SDO operation in a thread, under the SDO retry policy."""
        try:
            return await self.sdo_policy.run(
                lambda: asyncio.to_thread(fn), what=what, label=self.label, stats=self.stats
            )
        except DriveCommError:
            self._fresh_after = time.monotonic()
            raise

    def _on_tpdo(self, axis: Axis402, number: int) -> Callable[[Any], None]:
        def callback(_pdo: Any) -> None:  # canopen's receive thread
            axis.tpdo_time[number] = time.monotonic()
            loop, event = self._loop, self._tpdo_event
            if loop is not None and event is not None and not loop.is_closed():
                loop.call_soon_threadsafe(event.set)

        return callback

    def _heard(self, axis: Axis402, state: int) -> None:  # canopen's receive thread
        axis.heartbeat_time = time.monotonic()
        if state == 0:  # a boot-up message: the node forgot its configuration
            axis.booted = True
        loop, event = self._loop, self._tpdo_event
        if loop is not None and event is not None and not loop.is_closed():
            loop.call_soon_threadsafe(event.set)

    async def wait(self, predicate: Callable[[], bool], timeout: float) -> bool:
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
            except TimeoutError:
                return predicate()

    # -- connection ---------------------------------------------------------------------
    async def connect(self) -> None:
        """Identify the drive, start its nodes and enable them (see the module docstring).

        Connecting again (the loop does, after a failed configuration) starts afresh:
        the drive's nodes are forgotten first, never reported as "in use" by itself.
        """
        if self._added or self._shared is not None:
            await self.close()
        self._loop = asyncio.get_running_loop()
        self._tpdo_event = asyncio.Event()
        if self.network is None:
            assert self.channel is not None  # checked in __init__
            try:
                shared = await asyncio.to_thread(
                    SharedNetwork.acquire, self.interface, self.channel, self.bus_kwargs
                )
            except Exception as exc:  # noqa: BLE001 - python-can raises many kinds on a bad channel
                raise DriveCommError(f"{self.label}: cannot open the CAN bus: {exc}") from None
            self._shared, self.network = shared, shared.network
        try:
            first = self._add_node(self.node_id)
            count = await check_new(self, first)
            check_node_id(self.node_id, count)
            self.axes = [Axis402(first)]
            for k in range(1, count):
                self.axes.append(Axis402(self._add_node(self.node_id + k)))
            for k, axis in enumerate(self.axes):
                index = await self.sdo(
                    "axis index read", partial(getattr, axis.node.sdo[AXIS_INDEX_OBJECT], "raw")
                )
                if index != k:
                    raise DriveCommError(f"{self.label}: node {axis.node.id} is axis {index}, expected {k}")
                await self._start_axis(axis)
            self.axis_count = count
        except BaseException:
            await self.close()
            raise

    def _add_node(self, node_id: int) -> canopen.BaseNode402:
        if node_id in self._net.nodes:
            raise DriveCommError(f"{self.label}: node {node_id} is already in use on this network")
        node = canopen.BaseNode402(node_id, load_od(self.eds, node_id))
        node.sdo.RESPONSE_TIMEOUT = self.timeout_s
        self._net.add_node(node)
        self._added.append(node)
        return node

    async def _start_axis(self, axis: Axis402) -> None:
        node = axis.node

        def read_pdos() -> None:
            node.tpdo.read(from_od=self.pdo_from_eds)
            node.rpdo.read(from_od=self.pdo_from_eds)

        await self.sdo("PDO configuration read", read_pdos)
        node.setup_402_state_machine(read_pdos=False)
        for number, tpdo in node.tpdo.items():
            if tpdo.enabled:
                tpdo.add_callback(self._on_tpdo(axis, number))
        axis.guard_tpdos(self._net, self.label)
        node.emcy.add_callback(partial(log_emcy, self.label, int(node.id or 0)))
        node.nmt.add_heartbeat_callback(partial(self._heard, axis))
        if self.producer_heartbeat_ms:
            await self.sdo(
                "producer heartbeat write",
                lambda: setattr(node.sdo[0x1017], "raw", self.producer_heartbeat_ms),
            )
        node.nmt.state = "OPERATIONAL"  # NMT start: PDOs flow from now on
        # Every TPDO goes out once after NMT start; waiting for them means the state is
        # known before the 402 helper starts switching (a drive that stays silent fails
        # in _enable with a clear timeout).
        # some TPDOs may wait for their event timer; none at all is a node that did not start
        heard = await self.wait(
            lambda: all(n in axis.tpdo_time for n in axis.enabled_tpdos()), self.timeout_s * 2
        )
        if not heard and not axis.tpdo_time:
            raise DriveCommError(
                f"{self.label}: node {node.id} sent no TPDO within {self.timeout_s * 2:g} s of NMT start "
                "(it answers SDO: does it stay PRE-OPERATIONAL?)"
            )
        actual = await self.sdo("position read", lambda: node.sdo[0x6064].raw)
        if 0x607A in node.rpdo_pointers:
            target: Any = node.rpdo_pointers[0x607A]
            target.raw = actual  # no jump if a set-point slips through
        await enable(self, axis)

    async def close(self) -> None:
        """Forget the drive's nodes (the drives keep their state: a tracker holds)."""
        network = self.network
        if network is not None:
            for axis in self.axes:
                axis.unguard(network)
        for node in self._added:  # only the nodes this drive added: the network is shared
            if network is None:
                break
            for tpdo in node.tpdo.values():
                if tpdo.enabled and tpdo.cob_id:
                    with contextlib.suppress(KeyError, ValueError):
                        network.unsubscribe(tpdo.cob_id, tpdo.on_message)
            node.remove_network()
            network.nodes.pop(node.id, None)  # type: ignore[arg-type]  # set in _add_node
        self._added = []
        self.axes = []
        self.axis_count = 0
        if self._shared is not None:
            self._shared.release()
            self._shared = None
            self.network = None

    # -- state --------------------------------------------------------------------------
    async def _restart_if_rebooted(self) -> None:
        """A node that sent a boot-up message (a reboot, or an NMT reset, which forgets the
        consumer heartbeat too) is started afresh before it is used, and counted in
        ``restarts`` so that the loop configures the drive again.  A node that left
        OPERATIONAL without one was put there by another master (a service tool's NMT stop
        or pre-operational): it is held, not started again from here."""
        if any(a.booted for a in self.axes):
            log.warning("%s: a node announced a reboot or reset; starting the drive again", self.label)
            await self.connect()
            self.restarts += 1
            return
        for a in self.axes:
            state = a.node.nmt.state
            if a.heartbeat_time and state not in ("OPERATIONAL", "INITIALISING"):
                raise DriveHeld(
                    f"{self.label}: node {a.node.id} put in NMT {state} by another master; "
                    "not started again (an NMT start there, or a reboot, lifts it)"
                )

    async def read_state(self) -> DriveState:
        if not self.axes:
            raise DriveCommError(f"{self.label}: not connected")
        await self._restart_if_rebooted()
        if self._fresh_after:
            # after a failure, wait for TPDOs sent since: the cache may hold a past state
            since = self._fresh_after
            fresh = await self.wait(
                lambda: all(a.tpdo_time.get(n, 0.0) > since for a in self.axes for n in a.enabled_tpdos()),
                self.stale_s,
            )
            if not fresh:
                raise DriveCommError(f"{self.label}: no TPDOs since the link failed")
            self._fresh_after = 0.0
        recent = partial(all_fresh, self.axes, self.stale_s, self.producer_heartbeat_ms, self.label)
        if not recent():  # frames lost in a bus fault: the next ones put the cache right
            await self.wait(recent, self.stale_s)
        now = time.monotonic()
        axes = []
        for axis in self.axes:
            axis.check_fresh(now, self.stale_s, self.producer_heartbeat_ms, self.label)
            axes.append(axis.axis_state(self.label))
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
        await self._restart_if_rebooted()
        for k, (axis, raw) in enumerate(zip(self.axes, raws)):
            state = axis.state
            if state == State402.FAULT:
                continue  # read_state shows the fault; command(CLEAR_FAULT) recovers
            if state != State402.OPERATION_ENABLED:
                # a quick stop or a disable by a service tool or the drive's own panel
                raise DriveHeld(
                    f"{self.label}: axis {k} (node {axis.node.id}) is "
                    f"{state.name if state else 'in an unknown state'}, not "
                    "OPERATION ENABLED; not re-enabled automatically (lift it where it was set; a reboot lifts it too)"
                )
            try:
                await set_point(self, k, axis, raw)
            except DriveCommError:
                self._fresh_after = time.monotonic()
                raise

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        """Write targets, then read the state once it reflects them (like Modbus FC23).

        The effective target travels back in a TPDO; wait (at most ``timeout_s``) until
        each axis's TPDO shows the requested value or a TPDO mapping it has arrived since
        the write (the drive may have clamped the value).
        """
        await self.write_targets(angles_deg)
        t_written = time.monotonic()
        raws = [to_raw(_TARGET, a) for a in angles_deg]

        await self.wait(
            lambda: all(axis.reflects_target(raw, t_written) for axis, raw in zip(self.axes, raws)),
            self.timeout_s,
        )
        return await self.read_state()

    # -- heartbeat, commands, configuration -------------------------------------------------
    async def heartbeat(self) -> None:
        """Send the master's heartbeat (one frame per bus however many drives ask at once)."""
        network = self._net
        try:
            sent = send_master_heartbeat(network, self.master_node_id)
        except Exception as exc:  # noqa: BLE001 - python-can CanError, OSError on a pulled adapter
            self.stats.errors += 1
            raise DriveCommError(f"{self.label}: heartbeat not sent: {exc}") from None
        if sent:
            self.stats.transactions += 1

    async def identify(self) -> DriveIdentity:
        await self._restart_if_rebooted()  # a STOPPED node answers no SDO: held, not silent
        return await identify(self)

    async def command(self, cmd: Command) -> None:
        if not self.axes:
            raise DriveCommError(f"{self.label}: not connected")
        first = self.axes[0].node
        await self.sdo(f"command {cmd.name}", lambda: setattr(first.sdo[_IDX_COMMAND], "raw", int(cmd)))
        if cmd in (Command.CLEAR_FAULT, Command.RESUME):
            # An explicit operator command: bring every axis back to OPERATION ENABLED
            # (from FAULT through a fault-reset edge, which the 402 helper sends).
            for axis in self.axes:
                await reenable(self, axis, fault_reset=cmd == Command.CLEAR_FAULT)

    async def configure(
        self,
        *,
        heartbeat_timeout_s: float | None = None,
        soft_limits: Sequence[tuple[float, float]] | None = None,
        stow_angles: Sequence[float] | None = None,
    ) -> None:
        """Consumer heartbeat, soft limits and stow angles (see :mod:`.configure`)."""
        await configure_drive(
            self, heartbeat_timeout_s=heartbeat_timeout_s, soft_limits=soft_limits, stow_angles=stow_angles
        )

    async def read_configuration(self) -> DriveConfiguration:
        return await read_configuration(self)
