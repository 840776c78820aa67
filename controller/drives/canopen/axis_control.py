"""The CiA 402 handshakes of one axis of a :class:`~.drive.CanopenDrive`: enabling it at
connect, a new set-point (profile position), and bringing the axis back to OPERATION
ENABLED after a command."""

from __future__ import annotations

import logging
from functools import partial
from typing import TYPE_CHECKING, Any

import canopen

from firmware_protocol.canopen import CW_ENABLE_OPERATION, CW_NEW_SET_POINT, State402, Statusword

from ..base import DriveCommError, DriveHeld
from .axis import Axis402

if TYPE_CHECKING:
    from .drive import CanopenDrive

log = logging.getLogger(__name__)


class SetPointNotAcknowledged(Exception):
    """The drive did not raise statusword bit 12 for a new set-point in time."""


async def enable(drive: CanopenDrive, axis: Axis402) -> None:
    """Profile position mode and OPERATION ENABLED at connect (the 402 helper's blocking
    calls); an axis someone put in QUICK STOP is held, not enabled."""
    node = axis.node
    if axis.state == State402.QUICK_STOP_ACTIVE:  # someone's stop: a restart lifts none
        raise DriveHeld(
            f"{drive.label}: node {node.id} is in QUICK STOP; not enabled (lift it where it was set; a reboot lifts it too)"
        )

    def enable_operation() -> None:
        node.op_mode = "PROFILED POSITION"
        node.state = "OPERATION ENABLED"

    try:
        await drive.sdo("enable operation", enable_operation)
    except DriveCommError:
        if axis.state == State402.FAULT:
            # A faulted drive still connects: read_state reports the fault and
            # command(CLEAR_FAULT) recovers it.
            log.warning("%s: node %d is in FAULT", drive.label, node.id)
            return
        raise


def controlword(node: canopen.BaseNode402, cw: int) -> None:
    node.controlword = int(cw)  # RPDO transmit (non-blocking) or SDO fallback


async def set_point(drive: CanopenDrive, k: int, axis: Axis402, raw: int) -> None:
    """Profile-position handshake: target, controlword bit 4 up, wait for statusword bit 12,
    bit 4 down; an attempt without the acknowledge is retried (the drive's set-point
    policy).  An axis that faults meanwhile did not take it: read_state says so."""
    node = axis.node

    def ack() -> bool:
        return bool(axis.statusword & Statusword.SET_POINT_ACK)

    async def attempt() -> None:
        # The previous set-point's acknowledge must be down first.
        if ack():
            controlword(node, CW_ENABLE_OPERATION)
            await drive.wait(lambda: not ack(), drive.timeout_s)
        pointers: dict[int, Any] = node.rpdo_pointers
        if 0x607A in pointers:
            pointers[0x607A].raw = raw
            target_pdo = pointers[0x607A].pdo_parent
            if 0x6040 not in pointers or pointers[0x6040].pdo_parent is not target_pdo:
                target_pdo.transmit()
        else:
            await drive.sdo("target write", lambda: setattr(node.sdo[0x607A], "raw", raw))
        controlword(node, CW_NEW_SET_POINT)
        taken = await drive.wait(ack, drive.timeout_s)
        controlword(node, CW_ENABLE_OPERATION)
        if not taken and axis.state != State402.FAULT:
            raise SetPointNotAcknowledged(f"not acknowledged within {drive.timeout_s:g} s")

    await drive.set_point_policy.run(
        attempt, what=f"axis {k} set-point", label=drive.label, stats=drive.stats
    )


async def reenable(drive: CanopenDrive, axis: Axis402, fault_reset: bool) -> None:
    """Bring ``axis`` back to OPERATION ENABLED (from FAULT through a fault-reset edge, which
    the 402 helper sends).  After a fault reset that the fault survives (its cause is still
    there) the axis stays in FAULT, as a Modbus drive keeps FAULT_CODE after a CLEAR_FAULT:
    the drive's state, which read_state reports, not a link error."""
    if axis.state == State402.OPERATION_ENABLED:
        return
    faulted = axis.state == State402.FAULT
    if faulted:
        controlword(axis.node, 0)  # bit 7 low, so the next is an edge
    try:
        await drive.sdo("re-enable", partial(setattr, axis.node, "state", "OPERATION ENABLED"))
    except DriveCommError:
        if not (fault_reset and faulted and axis.state == State402.FAULT):
            raise
        log.info("%s: node %d stays in FAULT after a fault reset", drive.label, axis.node.id)
