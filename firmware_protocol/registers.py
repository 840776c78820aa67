"""The drive's Modbus register map: the single, declarative source of truth.

Everything else is generated from :data:`REGISTER_MAP`: the codecs both sides use, the
Markdown reference (``generated/REGISTERS.md``) and the C header for firmware authors
(``generated/heliotrack_drive.h``).

Conventions
-----------
- All registers are holding registers (function codes 3, 6, 16), 0-based addresses equal
  to the request addresses.
- 32-bit values take two registers, high word first ("big-endian word order", the order
  Modbus masters call ABCD).
- A value on the wire is ``round(engineering_value / scale)``; angles use 0.001 deg.
- Angles are the drive's axis angles in degrees.  For a dual-axis tracker axis 0 is the
  azimuth of the panel normal (clockwise from north) and axis 1 its elevation; for a
  single-axis row axis 0 is the rotation angle (pvlib's ``tracker_theta`` sign: positive
  turns the panel towards the west for a north-south axis).
- Per-axis registers repeat in blocks of :data:`AXIS_STRIDE` starting at
  :data:`AXIS_BASE`; axis ``k`` register ``r`` lives at ``AXIS_BASE + k*AXIS_STRIDE + r``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum, IntFlag

MAGIC = 0x4854  # "HT"
PROTOCOL_MAJOR = 1
PROTOCOL_MINOR = 0
PROTOCOL_VERSION = (PROTOCOL_MAJOR << 8) | PROTOCOL_MINOR
MAX_AXES = 2
AXIS_BASE = 32
AXIS_STRIDE = 16

#: Word sizes of the wire types.
TYPE_WORDS = {"uint16": 1, "int16": 1, "uint32": 2, "int32": 2}


@dataclass(frozen=True)
class Register:
    """One register (or register pair) in the map.

    Attributes
    ----------
    name : str
        Upper-case identifier, used for C macros and Python lookups.
    offset : int
        Address for global registers; offset inside the axis block for per-axis ones.
    type : str
        ``uint16``, ``int16``, ``uint32`` or ``int32``.
    scale : float
        Engineering value = raw * scale.
    unit : str
        Unit of the engineering value ("" for codes and counters).
    access : str
        ``"R"`` or ``"RW"``.
    description : str
        What it means, for the generated reference.
    per_axis : bool
        True when the register repeats for every axis.
    enum : str
        Name of the enum or flag type that decodes it ("" when numeric).
    """

    name: str
    offset: int
    type: str
    scale: float
    unit: str
    access: str
    description: str
    per_axis: bool = False
    enum: str = ""

    @property
    def words(self) -> int:
        return TYPE_WORDS[self.type]

    @property
    def signed(self) -> bool:
        return self.type.startswith("int")

    @property
    def writable(self) -> bool:
        return "W" in self.access

    def address(self, axis: int | None = None) -> int:
        """Absolute register address (axis index required for per-axis registers)."""
        if not self.per_axis:
            return self.offset
        if axis is None or not 0 <= axis < MAX_AXES:
            raise ValueError(f"{self.name} is per axis: axis must be 0..{MAX_AXES - 1}")
        return AXIS_BASE + axis * AXIS_STRIDE + self.offset


class Mode(IntEnum):
    """Operating mode of an axis (register ``MODE``)."""

    AUTO = 0  # follow TARGET_ANGLE
    STOW = 1  # go to STOW_ANGLE and stay until a RESUME command
    MANUAL = 2  # follow TARGET_ANGLE, set by an operator; watchdog still armed
    MAINTENANCE = 3  # motor disabled, brake on; ignores targets and the watchdog


class Command(IntEnum):
    """Values written to ``COMMAND``; the firmware executes them and resets it to NONE."""

    NONE = 0
    STOW = 1  # all axes to STOW mode
    RESUME = 2  # leave STOW (and COMM_LOST) for AUTO
    CLEAR_FAULT = 3  # clear latched faults if their cause is gone
    HOME = 4  # run the homing sequence: re-reference the encoder at the index


class Status(IntFlag):
    """Axis status bits (register ``STATUS``)."""

    MOVING = 1 << 0
    AT_TARGET = 1 << 1
    LIMIT_POS = 1 << 2  # at or beyond the positive soft limit
    LIMIT_NEG = 1 << 3  # at or beyond the negative soft limit
    STALLED = 1 << 4  # commanded but not moving
    FAULT = 1 << 5  # a latched fault: see FAULT_CODE
    STOWED = 1 << 6  # in STOW mode and at the stow angle
    COMM_LOST = 1 << 7  # the heartbeat watchdog expired
    TARGET_CLAMPED = 1 << 8  # last target was outside the soft limits and was clamped
    HOMED = 1 << 9  # encoder referenced
    WATCHDOG_STOW = 1 << 10  # in STOW because the heartbeat watchdog fired (latched until the
    # axis leaves STOW or a master commands STOW: COMM_LOST clears with the next heartbeat)


class Fault(IntEnum):
    """Latched fault codes (register ``FAULT_CODE``)."""

    NONE = 0
    STALL = 1  # motor current but no motion for the stall time
    HARD_LIMIT = 2  # a hard-limit switch tripped
    OVERCURRENT = 3
    ENCODER = 4  # encoder reading lost or implausible
    OVERTEMPERATURE = 5


GLOBAL_REGISTERS: tuple[Register, ...] = (
    Register("MAGIC", 0, "uint16", 1, "", "R", "Identification: 0x4854 (ASCII 'HT')."),
    Register("PROTOCOL_VERSION", 1, "uint16", 1, "", "R", "Protocol version, major * 256 + minor."),
    Register("AXIS_COUNT", 2, "uint16", 1, "", "R", "Number of axes this drive has (1 or 2)."),
    Register(
        "FIRMWARE_VERSION", 3, "uint16", 1, "", "R", "Firmware build, major * 256 + minor (informative)."
    ),
    Register("DEVICE_STATUS", 4, "uint16", 1, "", "R", "OR of all axes' STATUS bits.", enum="Status"),
    Register(
        "COMMAND",
        8,
        "uint16",
        1,
        "",
        "RW",
        "Write a command; the firmware executes it and resets the register to 0.",
        enum="Command",
    ),
    Register(
        "HEARTBEAT",
        9,
        "uint16",
        1,
        "",
        "RW",
        "Master writes a changing counter; if it does not change for "
        "HEARTBEAT_TIMEOUT the firmware sets COMM_LOST and stows every axis.",
    ),
    Register(
        "HEARTBEAT_TIMEOUT",
        10,
        "uint16",
        0.1,
        "s",
        "RW",
        "Watchdog timeout; 0 disables the watchdog (commissioning only).",
    ),
    Register("UPTIME", 12, "uint32", 1, "s", "R", "Seconds since power-up."),
)

AXIS_REGISTERS: tuple[Register, ...] = (
    Register(
        "TARGET_ANGLE",
        0,
        "int32",
        0.001,
        "deg",
        "RW",
        "Commanded axis angle; clamped to the soft limits (TARGET_CLAMPED set).",
        per_axis=True,
    ),
    Register(
        "ACTUAL_ANGLE",
        2,
        "int32",
        0.001,
        "deg",
        "R",
        "Measured axis angle (output-side encoder).",
        per_axis=True,
    ),
    Register("VELOCITY", 4, "int16", 0.001, "deg/s", "R", "Measured axis speed.", per_axis=True),
    Register("STATUS", 5, "uint16", 1, "", "R", "Status bits.", per_axis=True, enum="Status"),
    Register(
        "FAULT_CODE", 6, "uint16", 1, "", "R", "Latched fault, 0 when none.", per_axis=True, enum="Fault"
    ),
    Register("MODE", 7, "uint16", 1, "", "RW", "Operating mode.", per_axis=True, enum="Mode"),
    Register(
        "SOFT_LIMIT_MIN", 8, "int32", 0.001, "deg", "RW", "Lowest angle a target may ask for.", per_axis=True
    ),
    Register(
        "SOFT_LIMIT_MAX",
        10,
        "int32",
        0.001,
        "deg",
        "RW",
        "Highest angle a target may ask for.",
        per_axis=True,
    ),
    Register(
        "MAX_SPEED", 12, "uint16", 0.001, "deg/s", "RW", "Speed limit of the position loop.", per_axis=True
    ),
    Register(
        "STOW_ANGLE", 13, "int16", 0.01, "deg", "RW", "Angle the axis goes to in STOW mode.", per_axis=True
    ),
)

REGISTER_MAP: tuple[Register, ...] = GLOBAL_REGISTERS + AXIS_REGISTERS
BY_NAME: dict[str, Register] = {r.name: r for r in REGISTER_MAP}

#: Number of registers that hold every defined address (the emulator's memory size).
REGISTER_SPACE = AXIS_BASE + MAX_AXES * AXIS_STRIDE

#: The reference drive's power-up values (the emulator's, ``hil.drive``), in engineering
#: units: what the EDS gives as DefaultValue.  A real drive has its own; the controller
#: writes the watchdog, the limits and the stow angle at start-up and reads them back.
FACTORY: dict[str, float] = {
    "HEARTBEAT_TIMEOUT": 10.0,
    "SOFT_LIMIT_MIN": -180.0,
    "SOFT_LIMIT_MAX": 180.0,
    "MAX_SPEED": 1.0,
    "STOW_ANGLE": 0.0,
}

ENUMS = {"Mode": Mode, "Command": Command, "Status": Status, "Fault": Fault}


def register(name: str) -> Register:
    """Look up a register by name (raises KeyError with the known names)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise KeyError(f"unknown register {name!r}; known: {', '.join(BY_NAME)}") from None


def _check_layout() -> None:
    """Fail at import if two registers overlap: the map must be unambiguous."""
    used: dict[int, str] = {}
    for axis in range(MAX_AXES):
        for reg in REGISTER_MAP:
            if not reg.per_axis and axis:
                continue
            base = reg.address(axis if reg.per_axis else None)
            for w in range(reg.words):
                if base + w in used:
                    raise AssertionError(f"{reg.name} overlaps {used[base + w]} at {base + w}")
                used[base + w] = reg.name
            if reg.per_axis and reg.offset + reg.words > AXIS_STRIDE:
                raise AssertionError(f"{reg.name} overflows the axis block")
        for reg in GLOBAL_REGISTERS:
            if reg.offset + reg.words > AXIS_BASE:
                raise AssertionError(f"{reg.name} overlaps the axis blocks")


_check_layout()
