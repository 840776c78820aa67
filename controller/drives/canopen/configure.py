"""Writing a CANopen drive's configuration: consumer heartbeat, soft limits, stow angles,
and reading it back.

The limits and the stow angle go in an order a firmware with interlocks accepts at every
step (:func:`~controller.drives.soft_limits.soft_limit_steps`).  A confirmed SDO download
says the node took the bytes, not that its firmware keeps them, so the configuration is
read back afterwards as on Modbus.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import TYPE_CHECKING

from firmware_protocol import register
from firmware_protocol.canopen import mirror_index
from firmware_protocol.codec import to_raw

from ..base import DriveCommError, LinkSettingsError, soft_limit_steps
from ..configuration import DriveConfiguration, Tolerances, differences, not_taken

if TYPE_CHECKING:
    from .drive import CanopenDrive

LIMIT_MIN = register("SOFT_LIMIT_MIN")
LIMIT_MAX = register("SOFT_LIMIT_MAX")
STOW = register("STOW_ANGLE")
SPEED = register("MAX_SPEED")  # 0x6081, profile velocity
#: one step of the objects' units: 0x1016's ms, the limits' and the stow angle's scales
TOLERANCES = Tolerances(0.001, LIMIT_MIN.scale, STOW.scale)


async def configure_drive(
    drive: CanopenDrive,
    *,
    heartbeat_timeout_s: float | None = None,
    soft_limits: Sequence[tuple[float, float]] | None = None,
    stow_angles: Sequence[float] | None = None,
) -> None:
    if not drive.axes:
        raise DriveCommError(f"{drive.label}: not connected")
    if heartbeat_timeout_s is not None:
        ms = round(heartbeat_timeout_s * 1000)
        if not 0 <= ms <= 0xFFFF:
            raise LinkSettingsError(
                f"{drive.label}: heartbeat timeout {heartbeat_timeout_s:g} s "
                "outside the 0..65.535 s a CANopen consumer heartbeat "
                "time holds"
            )
        value = (drive.master_node_id << 16) | ms
        for axis in drive.axes:
            await drive.sdo(
                "consumer heartbeat write", partial(setattr, axis.node.sdo[0x1016][1], "raw", value)
            )
    limits, stows = list(soft_limits or ()), list(stow_angles or ())
    for k, (lo, hi) in enumerate(limits):
        if to_raw(LIMIT_MIN, lo) > to_raw(LIMIT_MAX, hi):
            raise ValueError(f"soft limits of axis {k}: min {lo} > max {hi}")
    for k in range(max(len(limits), len(stows))):
        node = drive.axes[k].node
        new = (limits[k][0], limits[k][1]) if k < len(limits) else None
        stow = stows[k] if k < len(stows) else None
        current = (0.0, 0.0)
        if new is not None and stow is not None:
            lo_raw = await drive.sdo("soft limit read", partial(getattr, node.sdo[0x607D][1], "raw"))
            hi_raw = await drive.sdo("soft limit read", partial(getattr, node.sdo[0x607D][2], "raw"))
            current = (lo_raw * LIMIT_MIN.scale, hi_raw * LIMIT_MAX.scale)
        for step in soft_limit_steps(current, new, stow):
            if isinstance(step, tuple):  # min first: valid on the way (see the steps)
                await drive.sdo(
                    "soft limit write",
                    partial(setattr, node.sdo[0x607D][1], "raw", to_raw(LIMIT_MIN, step[0])),
                )
                await drive.sdo(
                    "soft limit write",
                    partial(setattr, node.sdo[0x607D][2], "raw", to_raw(LIMIT_MAX, step[1])),
                )
            else:
                await drive.sdo(
                    "stow angle write",
                    partial(setattr, node.sdo[mirror_index(STOW)], "raw", to_raw(STOW, step)),
                )
    await _read_back(drive, heartbeat_timeout_s, limits, stows)


async def _read_back(
    drive: CanopenDrive,
    heartbeat_timeout_s: float | None,
    limits: list[tuple[float, float]],
    stows: list[float],
) -> None:
    got = drive.configuration = await read_configuration(drive)
    diffs = differences(
        got,
        TOLERANCES,
        heartbeat_timeout_s=heartbeat_timeout_s,
        soft_limits=limits,
        stow_angles=stows,
        producer=drive.master_node_id if heartbeat_timeout_s else None,
    )
    if diffs:
        raise DriveCommError(not_taken(drive.label, diffs))


async def read_configuration(drive: CanopenDrive) -> DriveConfiguration:
    """Every axis node's consumer heartbeat (0x1016:1), soft limits (0x607D) and stow angle.

    The watchdog's timeout is the longest of the axes' (a node that watches nothing, 0,
    counts as off only when every node is off)."""
    if not drive.axes:
        raise DriveCommError(f"{drive.label}: not connected")
    timeouts, producers, limits, stows, speeds = [], [], [], [], []
    for axis in drive.axes:
        sdo = axis.node.sdo
        value = await drive.sdo("consumer heartbeat read", partial(getattr, sdo[0x1016][1], "raw"))
        producer, ms = (value >> 16) & 0xFF, value & 0xFFFF
        timeouts.append(ms / 1000 if producer else 0.0)
        producers.append(producer)
        lo = await drive.sdo("soft limit read", partial(getattr, sdo[0x607D][1], "raw"))
        hi = await drive.sdo("soft limit read", partial(getattr, sdo[0x607D][2], "raw"))
        limits.append((lo * LIMIT_MIN.scale, hi * LIMIT_MAX.scale))
        stow = await drive.sdo("stow angle read", partial(getattr, sdo[mirror_index(STOW)], "raw"))
        stows.append(stow * STOW.scale)
        speed = await drive.sdo("speed limit read", partial(getattr, sdo[0x6081], "raw"))
        speeds.append(speed * SPEED.scale)
    watched = [p for p, t in zip(producers, timeouts) if t > 0]
    return DriveConfiguration(
        max(timeouts),
        tuple(limits),
        tuple(stows),
        heartbeat_producer=watched[0] if watched and len(set(watched)) == 1 else None,
        producers=tuple(producers),
        max_speeds=tuple(speeds),
    )
