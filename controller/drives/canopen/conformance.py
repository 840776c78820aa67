"""A CANopen drive against the heliotrack profile's rules (``docs/canopen.md``): the checks a
firmware engineer runs on a real drive before it meets the controller (``heliotrack protocol
conformance``), through the controller's own link.

Without ``may_move`` the checks write only what the drive already holds, or values it must
refuse with a named SDO abort code (and put back what a drive that wrongly takes them
changed); with it, the watchdog's stow and a quick stop are checked too.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from typing import Any

from firmware_protocol import Command, Mode, Status
from firmware_protocol.canopen import QUICK_STOP_OPTION, State402
from firmware_protocol.registers import FACTORY

from ..base import DriveCommError, DriveRefused
from ..conformance import FAIL, PASS, Check, in_order, refused
from .axis_control import reenable
from .drive import CanopenDrive

#: SDO abort codes (CiA 301) the rules name.
READ_ONLY, NO_SUBINDEX, VALUE_RANGE, DEVICE_STATE = 0x06010002, 0x06090011, 0x06090030, 0x08000022
MOVING_CHECKS = ("watchdog", "quick stop held, then enabled again")


async def _abort(drive: CanopenDrive, fn: Callable[[], Any]) -> int | None:
    """Run one SDO transfer: None when the node took it, else its abort code."""
    try:
        await drive.sdo("conformance", fn)
    except DriveRefused as exc:
        return int(getattr(exc.refusal, "code", -1))
    return None


async def run_checks(
    drive: CanopenDrive, *, may_move: bool = False, watchdog_s: float = 2.0
) -> AsyncIterator[Check]:
    """Connect and check ``drive`` (its axis 0's node); the checks are yielded as they
    finish, and the drive is closed at the end."""
    try:
        try:
            await drive.connect()
            ident = await drive.identify()
        except DriveCommError as exc:  # the controller could not even start: say why
            yield Check("identity and start", FAIL, str(exc))
            return
        v = ident.version_text
        yield Check(
            "identity and start",
            PASS,
            f"{drive.axis_count} axis node(s), protocol {v(ident.protocol_version)}, firmware "
            f"{v(ident.firmware_version)}; NMT started, OPERATION ENABLED",
        )
        async for check in in_order(
            _static_checks(drive), lambda: _moving_checks(drive, watchdog_s), MOVING_CHECKS, may_move
        ):
            yield check
    finally:
        await drive.close()


async def _static_checks(drive: CanopenDrive) -> AsyncIterator[Check]:
    axis = drive.axes[0]
    sdo = axis.node.sdo
    await drive.heartbeat()
    try:
        option = await drive.sdo("quick stop option code read", lambda: sdo.upload(0x605A, 0))
        modes = await drive.sdo("supported drive modes read", lambda: sdo.upload(0x6502, 0))
    except DriveCommError as exc:
        yield Check("profile objects (0x605A, 0x6502)", FAIL, str(exc))
    else:
        option_code, pp = int.from_bytes(option, "little", signed=True), int.from_bytes(modes, "little") & 1
        ok = option_code == QUICK_STOP_OPTION and pp
        yield Check(
            "profile objects (0x605A, 0x6502)",
            PASS if ok else FAIL,
            f"quick stop option {option_code} ({QUICK_STOP_OPTION} expected), profile position {'supported' if pp else 'missing'}",
        )
    here = await drive.sdo("position read", lambda: sdo.upload(0x6064, 0))
    yield refused(
        "a read-only object refused (0x6064)",
        await _abort(drive, lambda: sdo.download(0x6064, 0, here)),
        READ_ONLY,
        "abort",
    )
    yield refused(
        "a sub-index the object does not have refused (0x607D:3)",
        await _abort(drive, lambda: sdo.upload(0x607D, 3)),
        NO_SUBINDEX,
        "abort",
    )
    yield refused(
        "an unsupported mode of operation refused (0x6060 = 3)",
        await _abort(drive, lambda: sdo.download(0x6060, 0, (3).to_bytes(1, "little"))),
        VALUE_RANGE,
        "abort",
    )
    held = await drive.read_configuration()
    code = await _abort(drive, lambda: sdo.download(0x1016, 1, (0).to_bytes(4, "little")))
    yield refused("the watchdog off outside MAINTENANCE refused (0x1016:1 = 0)", code, DEVICE_STATE, "abort")
    if code is None:  # it took it: the watchdog back on
        await drive.configure(heartbeat_timeout_s=held.heartbeat_timeout_s)
    await drive.heartbeat()
    seen = await drive.wait(lambda: axis.heartbeat_time is not None, 3.0)
    yield Check(
        "heartbeat produced (0x1017)",
        PASS if seen else FAIL,
        "heard" if seen else "no heartbeat from the node within 3 s of asking for one a second",
    )
    try:
        await drive.configure(
            heartbeat_timeout_s=held.heartbeat_timeout_s or None,
            soft_limits=held.soft_limits,
            stow_angles=held.stow_angles,
        )
    except DriveCommError as exc:
        yield Check("configuration written and read back", FAIL, str(exc))
    else:
        yield Check("configuration written and read back", PASS, held.describe())


async def _moving_checks(drive: CanopenDrive, watchdog_s: float) -> AsyncIterator[Check]:
    held = drive.configuration
    await drive.configure(heartbeat_timeout_s=watchdog_s)
    await drive.heartbeat()
    await asyncio.sleep(watchdog_s + 1.0)  # no master heartbeat
    problems = []
    st = (await drive.read_state()).axes[0]
    if st.mode != Mode.STOW or not st.status & Status.COMM_LOST or not st.status & Status.WATCHDOG_STOW:
        problems.append(
            f"after {watchdog_s + 1:g} s without the master's heartbeat: {st.mode.name}, {st.status!r}"
        )
    await drive.heartbeat()
    await asyncio.sleep(0.3)
    st = (await drive.read_state()).axes[0]
    if st.status & Status.COMM_LOST or not st.status & Status.WATCHDOG_STOW:
        problems.append(f"after a heartbeat: {st.status!r} (COMM_LOST clear, WATCHDOG_STOW kept)")
    # the watchdog's timeout put back before the RESUME, which a short one would outrun (off
    # only in MAINTENANCE, which a drive here is not: the factory value then)
    await drive.configure(
        heartbeat_timeout_s=(held.heartbeat_timeout_s if held else 0.0) or FACTORY["HEARTBEAT_TIMEOUT"]
    )
    await drive.heartbeat()
    await drive.command(Command.RESUME)
    await asyncio.sleep(0.3)
    st = (await drive.read_state()).axes[0]
    if st.mode != Mode.AUTO:
        problems.append(f"after RESUME: {st.mode.name}")
    yield Check(
        MOVING_CHECKS[0],
        FAIL if problems else PASS,
        "; ".join(problems) or f"stowed after {watchdog_s:g} s, resumed",
    )

    axis = drive.axes[0]
    await drive.heartbeat()
    axis.node.controlword = 0x02  # quick stop
    stopped = await drive.wait(lambda: axis.state == State402.QUICK_STOP_ACTIVE, 2.0)
    await reenable(drive, axis, fault_reset=False)
    back = await drive.wait(lambda: axis.state == State402.OPERATION_ENABLED, 2.0)
    yield Check(
        MOVING_CHECKS[1],
        PASS if stopped and back else FAIL,
        f"QUICK STOP ACTIVE {'reached' if stopped else 'not reached'}, OPERATION ENABLED "
        f"{'again' if back else 'not reached again'} (option {QUICK_STOP_OPTION} stays stopped until enabled)",
    )
