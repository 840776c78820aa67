"""The drive firmware's register logic, independent of any transport.

:class:`DriveFirmware` owns the register memory defined by ``firmware_protocol`` and the
:class:`~hil.drive.axis.AxisModel` of each axis.  Transports (Modbus RTU/TCP here, CANopen
later) call :meth:`read` and :meth:`write`; both first bring the physics up to the time
given by the ``now`` callable, so the same firmware runs on the wall clock or on a
simulated one.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

from firmware_protocol import (
    MAGIC,
    PROTOCOL_VERSION,
    REGISTER_MAP,
    REGISTER_SPACE,
    Command,
    Fault,
    Mode,
    Status,
    decode,
    encode,
)
from firmware_protocol.registers import FACTORY, Register

from .axis import AxisModel, AxisParams

FIRMWARE_VERSION = 0x0100


def check_axis_params(p: AxisParams, k: int = 0) -> None:
    """Refuse physically meaningless parameters (ValueError naming the axis)."""
    problems = []
    if not p.max_speed > 0:
        problems.append(f"max_speed {p.max_speed} deg/s must be > 0")
    if not p.accel > 0:
        problems.append(f"accel {p.accel} deg/s^2 must be > 0")
    if p.backlash < 0 or p.encoder_resolution < 0 or p.deadband < 0 or p.stall_time <= 0:
        problems.append("backlash, encoder resolution and deadband must be >= 0, stall time > 0")
    if not p.hard_min <= p.soft_min < p.soft_max <= p.hard_max:
        problems.append(
            f"limits must satisfy hard_min <= soft_min < soft_max <= hard_max "
            f"({p.hard_min}, {p.soft_min}, {p.soft_max}, {p.hard_max})"
        )
    if not p.soft_min <= p.stow_angle <= p.soft_max:
        problems.append(f"stow angle {p.stow_angle} outside the soft limits")
    if problems:
        raise ValueError(f"axis {k}: " + "; ".join(problems))


class FirmwareReject(Exception):
    """A request the firmware refuses; ``code`` is the Modbus exception code (2 or 3)."""

    def __init__(self, code: int, why: str):
        super().__init__(why)
        self.code = code


# address -> (register, axis or None, word index) for every defined word
_WORDS: dict[int, tuple[Register, int | None, int]] = {}
for _reg in REGISTER_MAP:
    for _axis in range(2) if _reg.per_axis else [None]:
        for _w in range(_reg.words):
            _WORDS[_reg.address(_axis) + _w] = (_reg, _axis, _w)


class DriveFirmware:
    """Emulated firmware of a one- or two-axis slewing drive.

    Parameters
    ----------
    axes : sequence of AxisParams
        One entry per axis (1 or 2).
    now : callable
        Returns the current time in seconds (simulated, or the wall clock).
    heartbeat_timeout : float
        Initial watchdog timeout, s (0 disables it: commissioning only).
    monotonic : callable, optional
        The firmware's own time for physics, the watchdog and UPTIME (a real drive counts
        its own ticks); default ``now``.  Give a monotonic clock when ``now`` is a wall
        clock: a step of the wall clock must neither fire nor delay the watchdog.
    audit_limits : sequence of (min, max), optional
        Per axis, the travel the plant's configuration allows (deg): every target written
        outside it (or outside the axis's soft limits of the moment) is counted in
        :attr:`out_of_limit_writes`, whether the firmware clamps it or not.
    """

    def __init__(
        self,
        axes: Sequence[AxisParams],
        now: Callable[[], float],
        heartbeat_timeout: float = FACTORY["HEARTBEAT_TIMEOUT"],
        monotonic: Callable[[], float] | None = None,
        audit_limits: Sequence[tuple[float, float]] | None = None,
    ):
        if not 1 <= len(axes) <= 2:
            raise ValueError("a drive has 1 or 2 axes")
        if not heartbeat_timeout >= 0:
            raise ValueError(f"heartbeat timeout {heartbeat_timeout} s: must be >= 0")
        for k, p in enumerate(axes):
            check_axis_params(p, k)
        self.now = monotonic if monotonic is not None else now
        self.axes = [AxisModel(p) for p in axes]
        self.modes = [Mode.AUTO for _ in axes]
        self.clamped = [False for _ in axes]
        self.comm_lost = False
        #: The axis is in STOW because the watchdog fired (STATUS WATCHDOG_STOW).
        self.watchdog_stowed = [False for _ in axes]
        self.heartbeat = 0
        self.heartbeat_timeout = heartbeat_timeout
        self._t0 = self.now()
        self._t = self._t0
        self._last_heartbeat_change = self._t0
        self._lock = threading.RLock()
        self.transactions = 0
        #: Fault injection for transports: answer every request this much later (s).
        self.response_delay_s = 0.0
        # -- audit (what the world checks the controller against; not on the wire) --
        self.audit_limits = [tuple(lim) for lim in audit_limits] if audit_limits is not None else None
        #: TARGET_ANGLE writes received, and those outside the limits (see audit_limits).
        self.target_writes = 0
        self.out_of_limit_writes = 0
        #: The first few of them: (firmware time s, axis, value, the limits it broke, the
        #: firmware's own soft limits then), for a soak to show what went wrong.
        self.out_of_limit_samples: list[
            tuple[float, int, float, tuple[float, float], tuple[float, float]]
        ] = []
        #: The last target written to each axis (deg), whatever the mode did with it.
        self.last_target_written: list[float | None] = [None for _ in axes]
        #: The panel sits this far off each axis's output shaft (deg, a mounting or
        #: encoder offset of the row): the encoder and the position loop see the shaft,
        #: the sun sees the panel (:meth:`panel_angles`).
        self.mount_offsets: list[float] = [0.0 for _ in axes]

    @property
    def homed(self) -> list[bool]:
        """Each axis's encoder referenced (STATUS HOMED)."""
        return [ax.homed for ax in self.axes]

    @homed.setter
    def homed(self, value: list[bool]) -> None:
        for ax, h in zip(self.axes, value, strict=True):
            ax.homed = h

    # -- time ---------------------------------------------------------------------
    def update(self) -> None:
        """Advance physics and the watchdog to ``now()``."""
        with self._lock:
            t = self.now()
            dt = t - self._t
            if dt <= 0:
                return
            # Watchdog first: if it expired during the interval, stow from that instant.
            deadline = self._last_heartbeat_change + self.heartbeat_timeout
            if self.heartbeat_timeout > 0 and not self.comm_lost and t > deadline:
                before = max(deadline - self._t, 0.0)
                for ax in self.axes:
                    ax.advance(before)
                self._enter_comm_lost()
                dt = t - max(deadline, self._t)
            for ax in self.axes:
                ax.advance(dt)
            self._t = t

    def _enter_comm_lost(self) -> None:
        self.comm_lost = True
        for k in range(len(self.axes)):
            if self.modes[k] not in (Mode.MAINTENANCE, Mode.STOW):  # a stow keeps its owner
                self._set_mode(k, Mode.STOW)
                self.watchdog_stowed[k] = True

    def _set_mode(self, k: int, mode: Mode) -> None:
        ax = self.axes[k]
        self.modes[k] = mode
        self.watchdog_stowed[k] = False  # the stow's cause is whoever set the mode last
        ax.enabled = mode != Mode.MAINTENANCE
        if mode in (Mode.STOW, Mode.MAINTENANCE):
            ax.abort_homing()
        if mode == Mode.STOW:
            ax.target = ax.p.stow_angle

    # -- register view ------------------------------------------------------------
    def status(self, k: int) -> Status:
        ax = self.axes[k]
        s = Status(0)
        if ax.moving:
            s |= Status.MOVING
        if ax.at_target:
            s |= Status.AT_TARGET
        if ax.encoder >= ax.p.soft_max - ax.p.deadband:
            s |= Status.LIMIT_POS
        if ax.encoder <= ax.p.soft_min + ax.p.deadband:
            s |= Status.LIMIT_NEG
        if ax.stalled:
            s |= Status.STALLED
        if self.fault(k) != Fault.NONE:
            s |= Status.FAULT
        if self.modes[k] == Mode.STOW and ax.at_target:
            s |= Status.STOWED
        if self.comm_lost:
            s |= Status.COMM_LOST
        if self.watchdog_stowed[k] and self.modes[k] == Mode.STOW:
            s |= Status.WATCHDOG_STOW
        if self.clamped[k]:
            s |= Status.TARGET_CLAMPED
        if ax.homed:
            s |= Status.HOMED
        return s

    def fault(self, k: int) -> Fault:
        ax = self.axes[k]
        if ax.hard_limit:
            return Fault.HARD_LIMIT
        if ax.stalled:
            return Fault.STALL
        if ax.overheated:
            return Fault.OVERTEMPERATURE
        if ax.overcurrent:
            return Fault.OVERCURRENT
        return Fault.NONE

    def value(self, reg: Register, k: int | None) -> float | int:
        """Current engineering value of a register."""
        n = reg.name
        if k is not None:
            return self._axis_value(n, k) if k < len(self.axes) else 0
        match n:
            case "MAGIC":
                return MAGIC
            case "PROTOCOL_VERSION":
                return PROTOCOL_VERSION
            case "AXIS_COUNT":
                return len(self.axes)
            case "FIRMWARE_VERSION":
                return FIRMWARE_VERSION
            case "DEVICE_STATUS":
                s = Status(0)
                for j in range(len(self.axes)):
                    s |= self.status(j)
                return int(s)
            case "COMMAND":
                return 0
            case "HEARTBEAT":
                return self.heartbeat
            case "HEARTBEAT_TIMEOUT":
                return self.heartbeat_timeout
            case "UPTIME":
                return int(max(self._t - self._t0, 0))
        raise AssertionError(f"register {n} has no value")  # pragma: no cover

    def _axis_value(self, n: str, k: int) -> float | int:
        ax = self.axes[k]
        match n:
            case "TARGET_ANGLE":
                return ax.commanded
            case "ACTUAL_ANGLE":
                return ax.encoder
            case "VELOCITY":
                return max(min(ax.velocity, 32.0), -32.0)
            case "STATUS":
                return int(self.status(k))
            case "FAULT_CODE":
                return int(self.fault(k))
            case "MODE":
                return int(self.modes[k])
            case "SOFT_LIMIT_MIN":
                return ax.p.soft_min
            case "SOFT_LIMIT_MAX":
                return ax.p.soft_max
            case "MAX_SPEED":
                return ax.p.max_speed
            case "STOW_ANGLE":
                return ax.p.stow_angle
        raise AssertionError(f"register {n} has no value")  # pragma: no cover

    def read(self, address: int, count: int) -> list[int]:
        """Words ``address .. address+count-1``; undefined addresses read as 0.

        Raises FirmwareReject(2) beyond the register space.
        """
        if address < 0 or count < 1 or address + count > REGISTER_SPACE:
            raise FirmwareReject(2, f"read {address}+{count} outside 0..{REGISTER_SPACE - 1}")
        with self._lock:
            self.update()
            self.transactions += 1
            out = []
            for a in range(address, address + count):
                entry = _WORDS.get(a)
                if entry is None:
                    out.append(0)
                    continue
                reg, k, w = entry
                out.append(encode(reg, self.value(reg, k))[w])
            return out

    def write(self, address: int, values: Sequence[int]) -> None:
        """Apply a write of whole registers, or raise FirmwareReject without changing state."""
        with self._lock:
            self.update()
            self.transactions += 1
            changes = self._parse_write(address, values)
            for reg, k, value in changes:  # validated: now apply all of them
                self._apply(reg, k, value)

    def _parse_write(self, address: int, values: Sequence[int]):
        end = address + len(values)
        changes = []
        a = address
        while a < end:
            entry = _WORDS.get(a)
            if entry is None:
                raise FirmwareReject(2, f"no register at address {a}")
            reg, k, w = entry
            if w != 0 or a + reg.words > end:
                raise FirmwareReject(2, f"write splits the 32-bit register {reg.name}")
            if not reg.writable:
                raise FirmwareReject(2, f"{reg.name} is read-only")
            if k is not None and k >= len(self.axes):
                raise FirmwareReject(2, f"axis {k} does not exist on this drive")
            value = decode(reg, list(values[a - address : a - address + reg.words]))
            self._validate(reg, k, value)
            changes.append((reg, k, value))
            a += reg.words
        self._validate_together(changes)
        return changes

    def _validate(self, reg: Register, k: int | None, value) -> None:
        if reg.name == "MODE" and value not in Mode._value2member_map_:
            raise FirmwareReject(3, f"MODE {value} is not a mode")
        if reg.name == "COMMAND" and value not in Command._value2member_map_:
            raise FirmwareReject(3, f"COMMAND {value} is not a command")
        if reg.name == "MAX_SPEED" and not 0 < value <= 10:
            raise FirmwareReject(3, "MAX_SPEED must be in (0, 10] deg/s")
        if reg.name in ("SOFT_LIMIT_MIN", "SOFT_LIMIT_MAX") and k is not None:
            ax = self.axes[k]
            if not ax.p.hard_min <= value <= ax.p.hard_max:
                raise FirmwareReject(3, f"{reg.name} outside the hard limits")
        if reg.name == "MODE" and k is not None:
            # Leaving STOW needs COMMAND RESUME (which checks the link); after a comm
            # loss only STOW or MAINTENANCE may be chosen.
            if self.modes[k] == Mode.STOW and value in (Mode.AUTO, Mode.MANUAL):
                raise FirmwareReject(3, "leave STOW with COMMAND RESUME, not a MODE write")
            if self.comm_lost and value in (Mode.AUTO, Mode.MANUAL):
                raise FirmwareReject(3, "communication lost: RESUME after a heartbeat first")

    def _validate_together(self, changes) -> None:
        """Checks of the state the whole write would leave (limits written in one go)."""
        lo = {k: ax.p.soft_min for k, ax in enumerate(self.axes)}
        hi = {k: ax.p.soft_max for k, ax in enumerate(self.axes)}
        stow = {k: ax.p.stow_angle for k, ax in enumerate(self.axes)}
        modes = dict(enumerate(self.modes))
        timeout = None
        for reg, k, value in changes:
            match reg.name:
                case "SOFT_LIMIT_MIN":
                    lo[k] = value
                case "SOFT_LIMIT_MAX":
                    hi[k] = value
                case "STOW_ANGLE":
                    stow[k] = value
                case "MODE":
                    modes[k] = Mode(value)
                case "HEARTBEAT_TIMEOUT":
                    timeout = value
        for k in lo:
            if not lo[k] < hi[k]:
                raise FirmwareReject(3, f"axis {k}: soft limits [{lo[k]:g}, {hi[k]:g}] inverted")
            if not lo[k] <= stow[k] <= hi[k]:
                raise FirmwareReject(
                    3, f"axis {k}: stow angle {stow[k]:g} outside the soft limits [{lo[k]:g}, {hi[k]:g}]"
                )
        if timeout == 0 and any(m != Mode.MAINTENANCE for m in modes.values()):
            raise FirmwareReject(3, "the watchdog can be switched off only in MAINTENANCE")
        leaving = any(self.modes[k] == Mode.MAINTENANCE != modes[k] for k in modes)
        if leaving and (self.heartbeat_timeout if timeout is None else timeout) == 0:
            raise FirmwareReject(3, "the watchdog is off: set HEARTBEAT_TIMEOUT before leaving MAINTENANCE")

    def _apply(self, reg: Register, k: int | None, value) -> None:
        if k is not None:
            self._apply_axis(reg.name, k, value)
            return
        match reg.name:
            case "COMMAND":
                self._command(Command(value))
            case "HEARTBEAT":
                if value != self.heartbeat:
                    self.heartbeat = value
                    self._last_heartbeat_change = self._t
                    self.comm_lost = False
            case "HEARTBEAT_TIMEOUT":
                self.heartbeat_timeout = value
                self._last_heartbeat_change = self._t

    def _apply_axis(self, name: str, k: int, value) -> None:
        ax = self.axes[k]
        match name:
            case "TARGET_ANGLE":
                self._audit_target(k, value)
                if self.modes[k] in (Mode.AUTO, Mode.MANUAL):
                    clamped = min(max(value, ax.p.soft_min), ax.p.soft_max)
                    self.clamped[k] = clamped != value
                    ax.command(clamped)
            case "MODE":
                leaving = self.modes[k] == Mode.MAINTENANCE and value in (Mode.AUTO, Mode.MANUAL)
                self._set_mode(k, Mode(value))
                if leaving:  # hold where the service left it, as RESUME does: no slew to a stale target
                    ax.target = ax.encoder
            case "SOFT_LIMIT_MIN" | "SOFT_LIMIT_MAX":
                if name == "SOFT_LIMIT_MIN":
                    ax.p.soft_min = value
                else:
                    ax.p.soft_max = value
                if self.modes[k] in (Mode.AUTO, Mode.MANUAL):
                    # the target in force obeys the new limits at once (it had driven on outside them)
                    clamped = min(max(ax.commanded, ax.p.soft_min), ax.p.soft_max)
                    if clamped != ax.commanded:
                        self.clamped[k] = True
                        ax.command(clamped)
                    if ax.homing:  # the index too obeys them
                        ax.target = ax.index()
            case "MAX_SPEED":
                ax.p.max_speed = value
            case "STOW_ANGLE":
                ax.p.stow_angle = value
                if self.modes[k] == Mode.STOW:
                    ax.target = value

    def halt(self, k: int, angle_deg: float) -> None:
        """The drive stops axis ``k`` at ``angle_deg`` by itself (a CiA 402 halt, quick stop
        or fault reaction): the target its position loop then holds, within the soft
        limits.  Not a master's command, so the audit does not count it (an axis a hair
        past its limit, inside the deadband, is not a controller writing off limits)."""
        with self._lock:
            self.update()
            if self.modes[k] in (Mode.AUTO, Mode.MANUAL):
                ax = self.axes[k]
                ax.abort_homing()
                ax.target = min(max(angle_deg, ax.p.soft_min), ax.p.soft_max)

    def _audit_target(self, k: int, value: float) -> None:
        self.target_writes += 1
        self.last_target_written[k] = value
        tol = 0.0005  # half the register's quantum
        lo, hi = self.axes[k].p.soft_min, self.axes[k].p.soft_max
        if self.audit_limits is not None and k < len(self.audit_limits):
            lo, hi = max(lo, self.audit_limits[k][0]), min(hi, self.audit_limits[k][1])
        if not lo - tol <= value <= hi + tol:
            self.out_of_limit_writes += 1
            if len(self.out_of_limit_samples) < 10:
                p = self.axes[k].p
                self.out_of_limit_samples.append((self._t, k, value, (lo, hi), (p.soft_min, p.soft_max)))

    def _command(self, cmd: Command) -> None:
        for k, ax in enumerate(self.axes):
            match cmd:
                case Command.STOW:
                    if self.modes[k] != Mode.MAINTENANCE:
                        self._set_mode(k, Mode.STOW)
                case Command.RESUME:
                    if self.modes[k] == Mode.STOW and not self.comm_lost:
                        self._set_mode(k, Mode.AUTO)
                        ax.target = ax.encoder
                case Command.CLEAR_FAULT:
                    ax.clear_faults()
                case Command.HOME:
                    if self.modes[k] in (Mode.AUTO, Mode.MANUAL):
                        ax.start_homing()

    # -- truth for the world (not visible on the wire) -------------------------------
    def true_angles(self) -> list[float]:
        """Physical output angles (deg) at ``now()``: what the panel really does."""
        with self._lock:
            self.update()
            return [ax.output for ax in self.axes]

    def panel_angles(self) -> list[float]:
        """Where the panel really points (deg): the output angles plus the mounting offsets."""
        return [a + d for a, d in zip(self.true_angles(), self.mount_offsets)]
