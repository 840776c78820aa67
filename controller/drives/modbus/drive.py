"""Modbus RTU and TCP drive links over pymodbus's asyncio clients (``modbus-rtu``, ``modbus-tcp``)."""

from __future__ import annotations

import logging
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Any, Self

from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException

from firmware_protocol import (
    AXIS_STRIDE,
    MAGIC,
    PROTOCOL_VERSION,
    Command,
    Fault,
    Mode,
    Status,
    decode,
    encode,
    register,
)
from firmware_protocol.codec import axis_block_address, decode_axis

from ..base import (
    AxisState,
    DriveCommError,
    DriveIdentity,
    DriveLink,
    DriveRefused,
    DriveState,
    LinkStats,
    soft_limit_steps,
)
from ..configuration import DriveConfiguration, Tolerances, differences, not_taken
from ..links import LinkConfig, ModbusRtuLink, ModbusTcpLink
from .client import ModbusRefused, checked, endpoint, modbus_client, retry_policy, why_tcp_not_open

_ID_WORDS = 3


class ShortAnswer(ModbusException):
    """A read answered with fewer registers than asked (retried like a garbled frame)."""


_TARGET = register("TARGET_ANGLE")
log = logging.getLogger(__name__)
_LIMIT_MIN, _LIMIT_MAX = register("SOFT_LIMIT_MIN"), register("SOFT_LIMIT_MAX")
_STOW = register("STOW_ANGLE")
_SPEED = register("MAX_SPEED")
assert _SPEED.address(0) + _SPEED.words == _STOW.address(0)  # read together
#: a read-back within one register step of the value written is the value written
_TOLERANCES = Tolerances(register("HEARTBEAT_TIMEOUT").scale, _LIMIT_MIN.scale, _STOW.scale)


class ModbusDrive(DriveLink):
    """A drive on a pymodbus asyncio client (serial RTU or TCP).

    Parameters
    ----------
    client : pymodbus async client
        Or the :class:`~controller.drives.modbus.client.SharedSerialClient` of a port.
    device_id : int
        Modbus slave id of the drive.
    retries : int
        Extra attempts after a failed transaction.
    label : str
        Used in error messages (``"/dev/ttyUSB0 id 4"``).
    reopen : callable, optional
        Returns the client again after :meth:`close` (a shared line's client is released
        on close; connecting again must take the line's current one, not keep its own).
    """

    probe_policy = "policy"

    def __init__(
        self,
        client: Any,
        device_id: int,
        retries: int = 2,
        label: str = "",
        reopen: Callable[[], Any] | None = None,
    ):
        self.client = client
        self.reopen = reopen
        self.device_id = device_id
        self.retries = retries
        self.policy = retry_policy(retries)
        self.label = label or f"id {device_id}"
        self.axis_count = 0
        self.stats = LinkStats()
        self._beat = 0
        self._closed = False
        #: The drive answers FC 23 (read/write multiple registers); False once it refused it.
        self.fc23 = True

    async def _call(
        self, what: str, request: Callable[..., Awaitable[Any]], *args: Any, **kwargs: Any
    ) -> Any:
        """One request to this slave under the link's retry policy; an attempt on a client
        that lost its connection (a gateway restarted, a reply it could not decode) opens
        it again first."""

        async def attempt() -> Any:
            await self._reopen()
            return await checked(request, *args, device_id=self.device_id, **kwargs)

        return await self.policy.run(attempt, what=what, label=self.label, stats=self.stats)

    async def _reopen(self) -> None:
        """Open the client again if it lost its connection (an attempt fails if it cannot,
        and is retried like a request without an answer)."""
        if getattr(self.client, "connected", True):
            return
        try:
            opened = await self.client.connect()
        except DriveCommError as exc:  # a serial port: why it does not open
            raise ConnectionException(f"{self.label}: the link is down and does not reopen: {exc}") from None
        if not opened:
            raise ConnectionException(f"{self.label}: the link is down and does not reopen")

    async def _read(
        self, what: str, words: int, request: Callable[..., Awaitable[Any]], *args: Any, **kwargs: Any
    ) -> list[int]:
        """The first ``words`` registers of a read; an answer with fewer is garbled (and
        retried like one): a slave may send any byte count."""

        async def attempt() -> list[int]:
            await self._reopen()
            rr = await checked(request, *args, device_id=self.device_id, **kwargs)
            regs = list(getattr(rr, "registers", None) or ())
            if len(regs) < words:
                raise ShortAnswer(f"{len(regs)} register(s) in the answer, {words} asked")
            return regs[:words]

        return await self.policy.run(attempt, what=what, label=self.label, stats=self.stats)

    async def connect(self) -> None:
        if self._closed:  # connected again after close (the loop's reconnection)
            self._closed = False
            if self.reopen is not None:
                self.client = self.reopen()
        # a serial line's client raises DriveCommError naming the port and why it does not
        # open; a TCP client returns False
        t0 = time.monotonic()
        if not await self.client.connect():
            why = await why_tcp_not_open(self.client, time.monotonic() - t0)
            raise DriveCommError(f"{self.label}: cannot open the link{why}")
        words = await self._read(
            "identification read", _ID_WORDS, self.client.read_holding_registers, 0, count=_ID_WORDS
        )
        if words[0] != MAGIC:
            raise DriveCommError(f"{self.label}: not a heliotrack drive (register 0 = {words[0]:#06x})")
        if words[1] >> 8 != PROTOCOL_VERSION >> 8:
            raise DriveCommError(
                f"{self.label}: protocol {words[1] >> 8}.x, expected {PROTOCOL_VERSION >> 8}.x"
            )
        if not 1 <= words[2] <= 2:
            raise DriveCommError(f"{self.label}: implausible axis count {words[2]}")
        self.axis_count = words[2]

    async def close(self) -> None:
        if not self._closed:  # once: a shared line's client counts its users
            self._closed = True
            self.client.close()

    def _decode_state(self, words: Sequence[int]) -> DriveState:
        axes = []
        try:
            for k in range(self.axis_count):
                v = decode_axis(words, k * AXIS_STRIDE)
                axes.append(
                    AxisState(
                        actual_deg=float(v["ACTUAL_ANGLE"]),
                        target_deg=float(v["TARGET_ANGLE"]),
                        velocity_dps=float(v["VELOCITY"]),
                        status=Status(int(v["STATUS"])),
                        fault=Fault(int(v["FAULT_CODE"])),
                        mode=Mode(int(v["MODE"])),
                    )
                )
        except (ValueError, KeyError) as exc:  # an unknown mode or fault code on the wire
            raise DriveCommError(f"{self.label}: implausible state from the drive: {exc}") from None
        dev = Status(0)
        for a in axes:
            dev |= a.status
        return DriveState(self.axis_count, tuple(axes), dev)

    async def read_state(self) -> DriveState:
        n = AXIS_STRIDE * self.axis_count
        words = await self._read(
            "state read", n, self.client.read_holding_registers, axis_block_address(0), count=n
        )
        return self._decode_state(words)

    def _check(self, angles_deg: Sequence[float]) -> None:
        if len(angles_deg) != self.axis_count:
            raise ValueError(f"{self.label}: {len(angles_deg)} targets for {self.axis_count} axes")

    async def write_targets(self, angles_deg: Sequence[float]) -> None:
        self._check(angles_deg)
        for k, angle in enumerate(angles_deg):
            await self._call(
                "target write", self.client.write_registers, _TARGET.address(k), encode(_TARGET, angle)
            )

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        """Axis 1's target by FC16, then axis 0's target and the state read in one FC23; a
        drive without FC23 (exception 1) gets FC16 and FC3 from then on, one more
        transaction a cycle."""
        self._check(angles_deg)
        if not self.fc23:
            await self.write_targets(angles_deg)
            return await self.read_state()
        for k in range(1, self.axis_count):
            await self._call(
                "target write",
                self.client.write_registers,
                _TARGET.address(k),
                encode(_TARGET, angles_deg[k]),
            )
        try:
            words = await self._read(
                "target write + state read",
                AXIS_STRIDE * self.axis_count,
                self.client.readwrite_registers,
                read_address=axis_block_address(0),
                read_count=AXIS_STRIDE * self.axis_count,
                write_address=_TARGET.address(0),
                values=encode(_TARGET, angles_deg[0]),
            )
        except DriveRefused as exc:
            if not (isinstance(exc.refusal, ModbusRefused) and exc.refusal.code == ExcCodes.ILLEGAL_FUNCTION):
                raise
            self.fc23 = False
            log.warning(
                "%s: no FC 23 (read/write registers): targets by FC 16, state by FC 3 from now on", self.label
            )
            return await self.exchange(angles_deg)
        return self._decode_state(words)

    async def heartbeat(self) -> None:
        self._beat = (self._beat + 1) & 0xFFFF
        await self._call("heartbeat", self.client.write_register, register("HEARTBEAT").address(), self._beat)

    async def command(self, cmd: Command) -> None:
        await self._call(
            f"command {cmd.name}", self.client.write_register, register("COMMAND").address(), int(cmd)
        )

    async def configure(
        self,
        *,
        heartbeat_timeout_s: float | None = None,
        soft_limits: Sequence[tuple[float, float]] | None = None,
        stow_angles: Sequence[float] | None = None,
    ) -> None:
        if heartbeat_timeout_s is not None:
            reg = register("HEARTBEAT_TIMEOUT")
            await self._call(
                "configure", self.client.write_registers, reg.address(), encode(reg, heartbeat_timeout_s)
            )
        limits, stows = list(soft_limits or ()), list(stow_angles or ())
        for k in range(max(len(limits), len(stows))):
            new = (limits[k][0], limits[k][1]) if k < len(limits) else None
            stow = stows[k] if k < len(stows) else None
            current = await self._soft_limits(k) if new is not None and stow is not None else (0.0, 0.0)
            for step in soft_limit_steps(current, new, stow):
                if isinstance(step, tuple):
                    await self._call(
                        "configure",
                        self.client.write_registers,
                        _LIMIT_MIN.address(k),
                        encode(_LIMIT_MIN, step[0]) + encode(_LIMIT_MAX, step[1]),
                    )
                else:
                    await self._call(
                        "configure", self.client.write_registers, _STOW.address(k), encode(_STOW, step)
                    )
        await self._read_back(heartbeat_timeout_s, limits, stows)

    async def _read_back(
        self, heartbeat_timeout_s: float | None, limits: list[tuple[float, float]], stows: list[float]
    ) -> None:
        """The configuration as the drive holds it after the writes: a firmware that
        acknowledges and ignores them (its watchdog off, its factory limits) is refused."""
        got = self.configuration = await self.read_configuration()
        diffs = differences(
            got, _TOLERANCES, heartbeat_timeout_s=heartbeat_timeout_s, soft_limits=limits, stow_angles=stows
        )
        if diffs:
            raise DriveCommError(not_taken(self.label, diffs))

    async def read_configuration(self) -> DriveConfiguration:
        reg = register("HEARTBEAT_TIMEOUT")
        words = await self._read(
            "configuration read",
            reg.words,
            self.client.read_holding_registers,
            reg.address(),
            count=reg.words,
        )
        limits, stows, speeds = [], [], []
        n = _SPEED.words + _STOW.words  # adjacent: one read for both
        for k in range(self.axis_count):
            limits.append(await self._soft_limits(k))
            w = await self._read(
                "speed and stow angle read",
                n,
                self.client.read_holding_registers,
                _SPEED.address(k),
                count=n,
            )
            speeds.append(float(decode(_SPEED, w[: _SPEED.words])))
            stows.append(float(decode(_STOW, w[_SPEED.words :])))
        return DriveConfiguration(
            float(decode(reg, words)), tuple(limits), tuple(stows), max_speeds=tuple(speeds)
        )

    async def _soft_limits(self, k: int) -> tuple[float, float]:
        """Axis ``k``'s soft limits now (deg), in one read (the registers are adjacent)."""
        n = _LIMIT_MIN.words + _LIMIT_MAX.words
        words = await self._read(
            "soft limit read", n, self.client.read_holding_registers, _LIMIT_MIN.address(k), count=n
        )
        return (
            float(decode(_LIMIT_MIN, words[: _LIMIT_MIN.words])),
            float(decode(_LIMIT_MAX, words[_LIMIT_MIN.words :])),
        )

    async def identify(self) -> DriveIdentity:
        first, last = register("MAGIC"), register("UPTIME")
        n = last.address() + last.words - first.address()
        w = await self._read(
            "identification read", n, self.client.read_holding_registers, first.address(), count=n
        )

        def val(name: str) -> float:
            reg = register(name)
            a = reg.address() - first.address()
            return float(decode(reg, w[a : a + reg.words]))

        # the drive it connected to, still: another device at this address, or one that
        # came back from a reset without its identity, is not driven on as if it were
        if w[0] != MAGIC or int(val("PROTOCOL_VERSION")) >> 8 != PROTOCOL_VERSION >> 8:
            raise DriveCommError(
                f"{self.label}: identity changed (register 0 = {w[0]:#06x}, protocol "
                f"{int(val('PROTOCOL_VERSION')) >> 8}.x): not the heliotrack drive connected to"
            )
        if int(val("AXIS_COUNT")) != self.axis_count:
            raise DriveCommError(
                f"{self.label}: identity changed ({int(val('AXIS_COUNT'))} axes, {self.axis_count} at connect)"
            )
        return DriveIdentity(
            int(val("AXIS_COUNT")), int(val("PROTOCOL_VERSION")), int(val("FIRMWARE_VERSION")), val("UPTIME")
        )

    async def read_register(self, name: str, axis: int | None = None) -> float | int:
        reg = register(name)
        words = await self._read(
            f"read {name}", reg.words, self.client.read_holding_registers, reg.address(axis), count=reg.words
        )
        return decode(reg, words)

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> Self:
        """Slave (or unit) ``device_id`` on ``link``: an RTU line's shared client, or a TCP
        connection of its own (see :func:`~controller.drives.modbus.client.modbus_client`)."""
        if not isinstance(link, cls.config_type):
            raise TypeError(f"{cls.__name__} needs a {cls.config_type.__name__}, got {type(link).__name__}")
        return cls(
            modbus_client(link),
            device_id,
            link.retries,
            label=f"{endpoint(link)} id {device_id}",
            reopen=lambda: modbus_client(link),
        )


class ModbusRtuDrive(ModbusDrive):
    """A drive on a Modbus RTU line (link kind ``modbus-rtu``)."""

    config_type = ModbusRtuLink


class ModbusTcpDrive(ModbusDrive):
    """A drive behind Modbus TCP (link kind ``modbus-tcp``)."""

    config_type = ModbusTcpLink
