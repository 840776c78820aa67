"""A Modbus drive against the heliotrack register map's rules: the checks a firmware
engineer runs on a real drive before it meets the controller (``heliotrack protocol
conformance``).

Each check is one rule of ``firmware_protocol/generated/REGISTERS.md`` ("Behaviour"), run
through the controller's own link, so a drive that passes them is one ``run`` drives.  The
checks that move an axis or stow the drive run only with ``may_move``; the others write
only what the drive already holds, or values it must refuse (and restore what a drive that
wrongly takes them changed).
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

from firmware_protocol import MAGIC, Command, Mode, Status, decode, encode, register
from firmware_protocol.registers import AXIS_BASE, AXIS_STRIDE, REGISTER_MAP, REGISTER_SPACE

from ..base import DriveCommError
from ..conformance import FAIL, PASS, SKIP, WARN, Check, in_order, refused
from .client import ModbusRefused, checked
from .drive import ModbusDrive


def gaps(axis_count: int) -> list[int]:
    """The addresses in the register space that no register holds (per-axis registers of
    the axes the drive has)."""
    held: set[int] = set()
    for reg in REGISTER_MAP:
        for k in range(axis_count) if reg.per_axis else (None,):
            held.update(range(reg.address(k), reg.address(k) + reg.words))
    return [a for a in range(AXIS_BASE + axis_count * AXIS_STRIDE) if a not in held]


class _Probe:
    """Raw requests on a connected drive: ``(answer, None)`` or ``(None, exception code)``."""

    def __init__(self, drive: ModbusDrive):
        self.d = drive
        self.c = drive.client

    async def ask(
        self, request: Callable[..., Awaitable[Any]], *args: Any, **kwargs: Any
    ) -> tuple[Any, int | None]:
        try:
            return await checked(request, *args, device_id=self.d.device_id, **kwargs), None
        except ModbusRefused as exc:
            return None, exc.code

    async def read(self, address: int, count: int) -> tuple[list[int] | None, int | None]:
        rr, code = await self.ask(self.c.read_holding_registers, address, count=count)
        return (list(rr.registers) if rr is not None else None), code

    async def value(self, name: str, axis: int | None = None) -> float:
        reg = register(name)
        words, code = await self.read(reg.address(axis), reg.words)
        if words is None:
            raise RuntimeError(f"{name} not readable (exception {code})")
        return float(decode(reg, words))

    async def write(self, name: str, value: float, axis: int | None = None) -> int | None:
        reg = register(name)
        _, code = await self.ask(self.c.write_registers, reg.address(axis), encode(reg, value))
        return code

    async def beat(self) -> None:
        await self.d.heartbeat()


async def run_checks(
    drive: ModbusDrive, *, may_move: bool = False, watchdog_s: float = 2.0
) -> AsyncIterator[Check]:
    """Connect and check ``drive``; the checks are yielded as they finish.

    Parameters
    ----------
    drive : ModbusDrive
        Not yet connected; closed at the end.
    may_move : bool
        Run the checks that move axis 0 (by a few degrees at most) and stow the drive.
    watchdog_s : float
        The watchdog timeout the watchdog check sets (s); the check waits one second more.
    """
    try:
        try:
            await drive.connect()
            ident = await drive.identify()
        except DriveCommError as exc:  # the controller could not even start: say why
            yield Check("identity", FAIL, f"{exc} (one read of 0..13 across its gaps, which read 0)")
            return
        p = _Probe(drive)
        await p.beat()
        yield Check(
            "identity",
            PASS,
            f"{drive.axis_count} axis/axes, protocol {ident.version_text(ident.protocol_version)}, "
            f"firmware {ident.version_text(ident.firmware_version)}",
        )
        async for check in in_order(
            _static_checks(p, drive.axis_count),
            lambda: _moving_checks(p, watchdog_s),
            MOVING_CHECKS,
            may_move,
        ):
            yield check
    finally:
        await drive.close()


async def _static_checks(p: _Probe, n: int) -> AsyncIterator[Check]:
    holes = gaps(n)
    words, code = await p.read(0, AXIS_BASE + n * AXIS_STRIDE)
    if words is None:
        yield Check(
            "reads across the gaps", FAIL, f"a read of 0..{AXIS_BASE + n * AXIS_STRIDE - 1}: exception {code}"
        )
    elif any(words[a] for a in holes):
        yield Check("reads across the gaps", FAIL, f"gaps read {[a for a in holes if words[a]]} non-zero")
    else:
        yield Check("reads across the gaps", PASS, f"{len(holes)} gap addresses read 0")
    _, code = await p.read(REGISTER_SPACE - 1, 2)
    yield refused("a read beyond the map refused", code, 2)

    target = register("TARGET_ANGLE")
    now = await p.value("TARGET_ANGLE", 0)
    await p.beat()
    rr, code = await p.ask(
        p.c.readwrite_registers,
        read_address=AXIS_BASE,
        read_count=AXIS_STRIDE,
        write_address=target.address(0),
        values=encode(target, now),
    )
    yield (
        Check("FC 23 exchange", PASS, "target written, state read in one transaction")
        if rr is not None
        else Check(
            "FC 23 exchange",
            WARN,
            f"exception {code}: the controller uses FC 16 + FC 3 (one more transaction a cycle)",
        )
    )
    # the heartbeat round: HEARTBEAT written (a new value, far from the link's own counter)
    # and the identification read back in one FC 23
    beat, uptime = register("HEARTBEAT"), register("UPTIME")
    n_id = uptime.address() + uptime.words
    rr, code = await p.ask(
        p.c.readwrite_registers,
        read_address=0,
        read_count=n_id,
        write_address=beat.address(),
        values=[(int(await p.value("HEARTBEAT")) + 0x8000) & 0xFFFF],
    )
    regs = list(getattr(rr, "registers", None) or ())
    yield (
        Check("FC 23 heartbeat round", PASS, "heartbeat written, identification read in one transaction")
        if rr is not None and len(regs) >= n_id and regs[0] == MAGIC
        else Check(
            "FC 23 heartbeat round",
            WARN,
            (f"exception {code}" if rr is None else f"answer {regs[:3]}...")
            + ": the controller uses FC 6 + FC 3 for its heartbeat round (one more transaction a round)",
        )
    )
    actual = register("ACTUAL_ANGLE")
    _, code = await p.ask(
        p.c.write_registers, actual.address(0), encode(actual, await p.value("ACTUAL_ANGLE", 0))
    )
    yield refused("a read-only register refused", code, 2)
    _, code = await p.ask(p.c.write_register, target.address(0), encode(target, now)[0])
    yield refused("half of a 32-bit register refused", code, 2)
    if code is None:  # it took the high word alone: put the whole target back
        await p.write("TARGET_ANGLE", now, 0)
    _, code = await p.ask(p.c.write_register, holes[0], 0)
    yield refused(f"a write to a gap ({holes[0]}) refused", code, 2)
    yield refused("MODE 9 refused", await p.write("MODE", 9, 0), 3)
    timeout = await p.value("HEARTBEAT_TIMEOUT")
    code = await p.write("HEARTBEAT_TIMEOUT", 0)
    yield refused("the watchdog off outside MAINTENANCE refused", code, 3)
    if code is None:
        await p.write("HEARTBEAT_TIMEOUT", timeout)
    await p.beat()
    if n == 1:
        _, code = await p.ask(p.c.write_registers, target.address(1), encode(target, 0.0))
        yield refused("an axis the drive does not have refused", code, 2)
    limits = [(await p.value("SOFT_LIMIT_MIN", k), await p.value("SOFT_LIMIT_MAX", k)) for k in range(n)]
    try:  # what it holds, written again and read back
        await p.d.configure(heartbeat_timeout_s=timeout or None, soft_limits=limits)
    except DriveCommError as exc:
        yield Check("configuration written and read back", FAIL, str(exc))
    else:
        text = ", ".join(f"[{a:g}, {b:g}]" for a, b in limits)
        yield Check("configuration written and read back", PASS, f"watchdog {timeout:g} s, limits {text}")


MOVING_CHECKS = (
    "targets clamped to the soft limits",
    "new soft limits clamp the target in force",
    "watchdog",
    "STOW and RESUME",
)


async def _moving_checks(p: _Probe, watchdog_s: float) -> AsyncIterator[Check]:
    lo, hi = await p.value("SOFT_LIMIT_MIN", 0), await p.value("SOFT_LIMIT_MAX", 0)
    here = await p.value("ACTUAL_ANGLE", 0)
    await p.beat()
    await p.write("TARGET_ANGLE", hi + 1.0, 0)
    got, status = await p.value("TARGET_ANGLE", 0), Status(int(await p.value("STATUS", 0)))
    await p.write("TARGET_ANGLE", here, 0)
    ok = abs(got - hi) <= 0.001 and bool(status & Status.TARGET_CLAMPED)
    yield Check(
        MOVING_CHECKS[0],
        PASS if ok else FAIL,
        f"{hi + 1:g} asked: target {got:g}, TARGET_CLAMPED {bool(status & Status.TARGET_CLAMPED)}",
    )

    # a target in force on the side away from the stow angle, then a limit between it and
    # the axis (the stow angle must stay inside the limits, or the write is refused)
    await p.beat()
    stow = await p.value("STOW_ANGLE", 0)
    step = -2.0 if stow >= here else 2.0
    if not lo <= here + step <= hi:
        yield Check(MOVING_CHECKS[1], SKIP, f"no room beside {here:g} within [{lo:g}, {hi:g}]")
    else:
        name, edge, old = (
            ("SOFT_LIMIT_MIN", here - 1.0, lo) if step < 0 else ("SOFT_LIMIT_MAX", here + 1.0, hi)
        )
        await p.write("TARGET_ANGLE", here + step, 0)
        code = await p.write(name, edge, 0)
        got = await p.value("TARGET_ANGLE", 0)
        await p.write(name, old, 0)
        await p.write("TARGET_ANGLE", here, 0)
        ok = code is None and abs(got - edge) <= 0.001
        why = f"refused: exception {code}" if code is not None else f"target reads {got:g}"
        yield Check(MOVING_CHECKS[1], PASS if ok else FAIL, f"target {here + step:g}, {name} {edge:g}: {why}")

    timeout = await p.value("HEARTBEAT_TIMEOUT")
    await p.write("HEARTBEAT_TIMEOUT", watchdog_s)
    await p.beat()
    await asyncio.sleep(watchdog_s + 1.0)  # no heartbeat
    status, mode = Status(int(await p.value("STATUS", 0))), Mode(int(await p.value("MODE", 0)))
    problems = []
    if not status & Status.COMM_LOST or mode != Mode.STOW or not status & Status.WATCHDOG_STOW:
        problems.append(f"after {watchdog_s + 1:g} s without a heartbeat: {mode.name}, {status!r}")
    if await p.write("MODE", int(Mode.AUTO), 0) != 3:
        problems.append("MODE AUTO not refused while COMM_LOST")
    await p.beat()
    status, mode = Status(int(await p.value("STATUS", 0))), Mode(int(await p.value("MODE", 0)))
    if status & Status.COMM_LOST or mode != Mode.STOW or not status & Status.WATCHDOG_STOW:
        problems.append(f"after a heartbeat: {mode.name}, {status!r} (COMM_LOST clear, WATCHDOG_STOW kept)")
    await p.write("COMMAND", int(Command.RESUME))
    mode = Mode(int(await p.value("MODE", 0)))
    target, actual = await p.value("TARGET_ANGLE", 0), await p.value("ACTUAL_ANGLE", 0)
    if mode != Mode.AUTO or abs(target - actual) > 2.0:  # holding where it stood, give or take a stop
        problems.append(f"after RESUME: {mode.name}, target {target:g} at {actual:g} (AUTO, holding)")
    await p.write("HEARTBEAT_TIMEOUT", timeout)
    yield Check(
        MOVING_CHECKS[2],
        FAIL if problems else PASS,
        "; ".join(problems) or f"stowed after {watchdog_s:g} s, resumed",
    )

    await p.beat()
    await p.write("COMMAND", int(Command.STOW))
    status, mode = Status(int(await p.value("STATUS", 0))), Mode(int(await p.value("MODE", 0)))
    problems = []
    if mode != Mode.STOW or status & Status.WATCHDOG_STOW:
        problems.append(f"after STOW: {mode.name}, {status!r}")
    if await p.write("MODE", int(Mode.AUTO), 0) != 3:
        problems.append("MODE AUTO not refused in STOW")
    await p.write("COMMAND", int(Command.RESUME))
    if Mode(int(await p.value("MODE", 0))) != Mode.AUTO:
        problems.append("RESUME did not return to AUTO")
    yield Check(
        MOVING_CHECKS[3],
        FAIL if problems else PASS,
        "; ".join(problems) or "stowed, MODE write refused, resumed",
    )
