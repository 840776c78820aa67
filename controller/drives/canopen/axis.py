"""The master's bookkeeping of one drive axis (one CiA 402 node): what its TPDOs said, and
when they and its heartbeat were last heard."""

from __future__ import annotations

import contextlib
import io
import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import canopen
from canopen.objectdictionary import eds as eds_format

from firmware_protocol import Fault, Mode, Status, register
from firmware_protocol.canopen import FAULT_ERROR_CODES, State402, mirror_index, state_from_statusword
from firmware_protocol.eds import eds

from ..base import AxisState, DriveCommError

log = logging.getLogger(__name__)

_TARGET = register("TARGET_ANGLE")
_ACTUAL = register("ACTUAL_ANGLE")
_VELOCITY = register("VELOCITY")
IDX_STATUS = mirror_index(register("STATUS"))
IDX_FAULT = mirror_index(register("FAULT_CODE"))
IDX_MODE = mirror_index(register("MODE"))
#: The target the firmware works with (after clamping), mirrored in a TPDO.
IDX_EFFECTIVE_TARGET = mirror_index(_TARGET)


def load_od(eds_path: str | Path | None, node_id: int) -> canopen.ObjectDictionary:
    """The object dictionary of node ``node_id``: from ``eds_path``, or the generated one."""
    if eds_path is None:
        return eds_format.import_eds(io.StringIO(eds()), node_id)
    return canopen.import_od(str(eds_path), node_id)


class Axis402:
    """One axis: its ``BaseNode402`` and the reception times of its TPDOs and heartbeat.

    Times are ``time.monotonic()`` seconds, written by canopen's receive thread.
    """

    def __init__(self, node: canopen.BaseNode402):
        self.node = node
        self.tpdo_time: dict[int, float] = {}  # TPDO number -> monotonic reception
        self.heartbeat_time: float | None = None
        #: The node sent a boot-up message (a reboot, or an NMT reset) since it was started.
        self.booted = False
        #: TPDO frames of the wrong length, dropped whole (see :meth:`guard_tpdos`).
        self.bad_length = 0
        self._guards: list[tuple[int, Callable[[int, bytearray, float], None], Callable[..., None]]] = []
        self._said = -float("inf")

    def guard_tpdos(self, network: canopen.Network, label: str) -> None:
        """Put a length check in front of each enabled TPDO and of the node's EMCY: a frame
        shorter or longer than its layout is dropped whole and counted, with a warning at
        most once a minute.  canopen had decoded a short TPDO object by object, updating the
        statusword and leaving the position stale, and logged an error for every frame (ten
        a second); a short EMCY was an error naming no node."""
        frames = [
            (pdo.cob_id, pdo.on_message, (pdo.length + 7) // 8, f"TPDO{number}")
            for number, pdo in self.node.tpdo.items()
            if pdo.enabled and pdo.cob_id
        ]
        frames.append((0x80 + int(self.node.id or 0), self.node.emcy.on_emcy, 8, "EMCY"))
        for cob_id, handler, need, what in frames:

            def guard(
                can_id: int, data: bytearray, timestamp: float, handler=handler, need=need, what=what
            ) -> None:
                if len(data) == need:
                    handler(can_id, data, timestamp)
                    return
                self.bad_length += 1
                if time.monotonic() - self._said >= 60.0:
                    self._said = time.monotonic()
                    log.warning(
                        "%s: %s from node %d has %d bytes, its layout needs %d: dropped (%d so far)",
                        label,
                        what,
                        self.node.id,
                        len(data),
                        need,
                        self.bad_length,
                    )

            network.unsubscribe(cob_id, handler)
            network.subscribe(cob_id, guard)
            self._guards.append((cob_id, guard, handler))

    def unguard(self, network: canopen.Network) -> None:
        """The guards off, canopen's own handlers back (its ``remove_network`` takes them off)."""
        for cob_id, guard, handler in self._guards:
            with contextlib.suppress(KeyError, ValueError):
                network.unsubscribe(cob_id, guard)
            network.subscribe(cob_id, handler)
        self._guards = []

    @property
    def statusword(self) -> int:
        """The last statusword a TPDO carried (0 before any)."""
        return int(self.node.tpdo_values.get(0x6041, 0))

    @property
    def state(self) -> State402 | None:
        return state_from_statusword(self.statusword)

    def enabled_tpdos(self) -> list[int]:
        return [n for n, pdo in self.node.tpdo.items() if pdo.enabled]

    def tpdos_mapping(self, index: int) -> list[int]:
        """Numbers of the enabled TPDOs that carry object ``index``."""
        return [
            n for n, pdo in self.node.tpdo.items() if pdo.enabled and any(v.index == index for v in pdo.map)
        ]

    def reflects_target(self, raw: int, since: float) -> bool:
        """The drive's effective target is ``raw``, or every TPDO carrying it has been heard
        since ``since`` (the drive took the set-point and clamped it)."""
        if self.node.tpdo_values.get(IDX_EFFECTIVE_TARGET) == raw:
            return True
        return all(self.tpdo_time.get(n, 0.0) > since for n in self.tpdos_mapping(IDX_EFFECTIVE_TARGET))

    def staleness(self, now: float, stale_s: float, producer_heartbeat_ms: int, label: str) -> str | None:
        """Why the cached state is no longer the drive's, or None: the node's heartbeat
        stopped (three periods) or one of its TPDOs is older than ``stale_s``."""
        node = self.node
        if (
            self.heartbeat_time is not None
            and now - self.heartbeat_time > 3 * producer_heartbeat_ms / 1000 > 0
        ):
            return f"{label}: heartbeat of node {node.id} lost"
        for number in self.enabled_tpdos():
            t = self.tpdo_time.get(number)
            if t is None or now - t > stale_s:
                return f"{label}: no TPDO{number} from node {node.id} for {stale_s:g} s"
        return None

    def check_fresh(self, now: float, stale_s: float, producer_heartbeat_ms: int, label: str) -> None:
        """Refuse a state that is no longer the drive's.

        Raises
        ------
        DriveCommError
            The node left OPERATIONAL, or its state is stale (:meth:`staleness`).
        """
        node = self.node
        if node.nmt.state not in ("OPERATIONAL", "INITIALISING") and self.heartbeat_time:
            raise DriveCommError(
                f"{label}: node {node.id} left OPERATIONAL (NMT {node.nmt.state}); reconnect"
            )
        why = self.staleness(now, stale_s, producer_heartbeat_ms, label)
        if why is not None:
            raise DriveCommError(why)

    def axis_state(self, label: str) -> AxisState:
        """The axis as its last TPDOs describe it (degrees, deg/s).

        Raises
        ------
        DriveCommError
            An object the state needs is not mapped, or a code on the wire is unknown.
        """
        v = self.node.tpdo_values
        try:
            status, fault = Status(int(v[IDX_STATUS])), Fault(int(v[IDX_FAULT]))
            if self.state in (State402.FAULT, State402.FAULT_REACTION_ACTIVE) and not status & Status.FAULT:
                # the 402 layer holds a fault the heliotrack mirror does not show (cleared
                # locally, or the drive's own): it drops every set-point until a fault reset
                status |= Status.FAULT
                fault = fault_of_error_code(int(v.get(0x603F, 0)))
            return AxisState(
                actual_deg=v[0x6064] * _ACTUAL.scale,
                target_deg=v[IDX_EFFECTIVE_TARGET] * _TARGET.scale,
                velocity_dps=v[0x606C] * _VELOCITY.scale,
                status=status,
                fault=fault,
                mode=Mode(int(v[IDX_MODE])),
            )
        except KeyError as exc:
            raise DriveCommError(
                f"{label}: node {self.node.id} does not map 0x{exc.args[0]:04X} in a TPDO"
            ) from None
        except ValueError as exc:  # an unknown fault or mode code on the wire
            raise DriveCommError(f"{label}: implausible state from node {self.node.id}: {exc}") from None


def log_emcy(label: str, node_id: int, err: canopen.emcy.EmcyError) -> None:  # canopen's receive thread
    """An EMCY a node sent, logged: the fault reaches the state through the TPDOs, but the
    EMCY is the drive's word for it (a vendor's code included), for a field engineer."""
    if err.code:
        log.warning(
            "%s: EMCY from node %d: 0x%04X (error register 0x%02X)", label, node_id, err.code, err.register
        )


def fault_of_error_code(code: int) -> Fault:
    """The heliotrack fault of a CiA 402 error code (0x603F); an unknown or zero code (the
    402 FAULT state alone) counts as an encoder / firmware fault, the most general."""
    for fault, c in FAULT_ERROR_CODES.items():
        if c == code and fault != Fault.NONE:
            return fault
    return Fault.ENCODER


def all_fresh(axes: Sequence[Axis402], stale_s: float, producer_heartbeat_ms: int, label: str) -> bool:
    """Every axis's heartbeat and TPDOs are recent now (:meth:`Axis402.staleness`)."""
    now = time.monotonic()
    return all(a.staleness(now, stale_s, producer_heartbeat_ms, label) is None for a in axes)
