"""Who a CANopen drive is: the mirrors of the heliotrack global registers (magic, protocol
and firmware versions, axis count, uptime), read by SDO from the node of axis 0."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

import canopen

from firmware_protocol import MAGIC, PROTOCOL_VERSION, register
from firmware_protocol.canopen import mirror_index

from ..base import DriveCommError, DriveIdentity

if TYPE_CHECKING:
    from .drive import CanopenDrive

IDX_MAGIC = mirror_index(register("MAGIC"))


async def read_globals(drive: CanopenDrive, node: canopen.BaseNode402, *names: str) -> list[float]:
    """The global registers ``names`` as ``node`` mirrors them (in their units)."""

    def read(name: str) -> float:
        reg = register(name)
        return float(node.sdo[mirror_index(reg)].raw * reg.scale)

    return [await drive.sdo("identification read", partial(read, n)) for n in names]


async def check_new(drive: CanopenDrive, node: canopen.BaseNode402) -> int:
    """At connect: a heliotrack drive of this protocol's major version; its axis count.

    Raises
    ------
    DriveCommError
        Another device, another protocol, or an axis count other than 1 or 2.
    """
    (magic,) = await read_globals(drive, node, "MAGIC")
    if magic != MAGIC:
        raise DriveCommError(f"{drive.label}: not a heliotrack drive (0x{IDX_MAGIC:04X} = {int(magic):#06x})")
    (version,) = await read_globals(drive, node, "PROTOCOL_VERSION")
    if int(version) >> 8 != PROTOCOL_VERSION >> 8:
        raise DriveCommError(
            f"{drive.label}: protocol {int(version) >> 8}.x, expected {PROTOCOL_VERSION >> 8}.x"
        )
    (count,) = await read_globals(drive, node, "AXIS_COUNT")
    if not 1 <= count <= 2:
        raise DriveCommError(f"{drive.label}: implausible axis count {int(count)}")
    return int(count)


async def identify(drive: CanopenDrive) -> DriveIdentity:
    """The drive's identity now; the one connected to, still (as on Modbus).

    Raises
    ------
    DriveCommError
        Not connected, or another device answers at the node id (magic, protocol major or
        axis count changed).
    """
    if not drive.axes:
        raise DriveCommError(f"{drive.label}: not connected")
    magic, count, protocol, firmware, uptime = await read_globals(
        drive, drive.axes[0].node, "MAGIC", "AXIS_COUNT", "PROTOCOL_VERSION", "FIRMWARE_VERSION", "UPTIME"
    )
    if magic != MAGIC or int(protocol) >> 8 != PROTOCOL_VERSION >> 8 or count != drive.axis_count:
        raise DriveCommError(
            f"{drive.label}: identity changed (0x{IDX_MAGIC:04X} = {int(magic):#06x}, protocol "
            f"{int(protocol) >> 8}.x, {int(count)} axes; {drive.axis_count} at connect): "
            "not the drive connected to"
        )
    return DriveIdentity(int(count), int(protocol), int(firmware), uptime)
