"""The drive's CANopen object dictionary (CiA 301 + CiA 402), generated from the register map.

One CANopen node per drive *axis* (decision, see ``docs/canopen.md``): a drive with
``--id N`` and two axes answers as nodes ``N`` (axis 0) and ``N + 1`` (axis 1).  Every node
is then a plain single-axis CiA 402 device that any 402 master (canopen's ``BaseNode402``
included) can drive, and each axis gets its own four TPDOs.  The CiA 402 multi-axis offset
(+0x800) was rejected because generic masters, ``BaseNode402`` among them, only know the
0x6040/0x6041 block.

Where the Modbus register map (:mod:`firmware_protocol.registers`) and CANopen overlap, the
objects are derived from the same :class:`~firmware_protocol.registers.Register` entries:

- every register is mirrored in the manufacturer range, global register at offset ``o`` as
  object ``0x2000 + o``, per-axis register at offset ``o`` as ``0x2100 + o``, with the
  register's type and scale (positions in 0.001 deg, exactly as on Modbus);
- registers with a CiA 301/402 counterpart (:data:`STANDARD_ALIASES`) are written through
  the standard object; their manufacturer mirror is then read-only, so there is one write
  path per quantity;
- ``HEARTBEAT`` has no object: the CANopen heartbeat protocol (0x1016/0x1017) replaces it.

Nothing here imports ``canopen``: the EDS is plain INI text (CiA 306).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from .cia402 import (  # noqa: F401 - part of this module's vocabulary
    CW_ENABLE_OPERATION,
    CW_NEW_SET_POINT,
    STATE_BITS,
    Controlword,
    State402,
    Statusword,
    state_from_statusword,
)
from .registers import (
    AXIS_REGISTERS,
    FACTORY,
    GLOBAL_REGISTERS,
    MAGIC,
    MAX_AXES,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Fault,
    Register,
)

EDS_NAME = "heliotrack_drive.eds"

#: CiA 301 data type codes used here.
BOOLEAN, INTEGER8, INTEGER16, INTEGER32 = 0x1, 0x2, 0x3, 0x4
UNSIGNED8, UNSIGNED16, UNSIGNED32, VISIBLE_STRING = 0x5, 0x6, 0x7, 0x9
TYPE_BITS = {
    INTEGER8: 8,
    INTEGER16: 16,
    INTEGER32: 32,
    UNSIGNED8: 8,
    UNSIGNED16: 16,
    UNSIGNED32: 32,
    BOOLEAN: 1,
}
_REG_TYPES = {"uint16": UNSIGNED16, "int16": INTEGER16, "uint32": UNSIGNED32, "int32": INTEGER32}

VAR, ARRAY, RECORD = 0x7, 0x8, 0x9

GLOBAL_MIRROR_BASE = 0x2000
AXIS_MIRROR_BASE = 0x2100
AXIS_INDEX_OBJECT = 0x2020  # CANopen only: which axis of the drive this node is
DEVICE_TYPE = 0x00020192  # CiA 402 profile (0x192), servo drive (additional info 2)
VENDOR_ID = 0x00000000  # no CiA vendor id assigned; identify by product code
PRODUCT_CODE = MAGIC
REVISION = (PROTOCOL_MAJOR << 16) | PROTOCOL_MINOR
DEFAULT_PRODUCER_HEARTBEAT_MS = 1000
#: TPDO event timers, ms, by TPDO number.  TPDO1/2 (statusword, mode display) repeat
#: every 100 ms because canopen's BaseNode402, once it has seen a TPDO twice, waits at most
#: 0.2 s for the next one; TPDO3/4 (velocity/target, error code) change with TPDO1/2 and
#: only need a keep-alive.  Every TPDO is also sent at once when its content changes.
TPDO_EVENT_TIMER_MS = {1: 100, 2: 100, 3: 1000, 4: 1000}
#: Node id the drives expect the master's heartbeat from unless 0x1016:1 says otherwise.
MASTER_NODE_ID = 0x7F
#: Highest node id a drive may use (the master takes 0x7F).
MAX_NODE_ID = 0x7E
PROFILE_POSITION = 1  # 0x6060 value: the only mode of operation supported
QUICK_STOP_OPTION = 6  # 0x605A: stop, then stay in QUICK STOP ACTIVE
SUPPORTED_DRIVE_MODES = 0x1  # 0x6502 bit 0: profile position

#: Register name -> (index, subindex) of the standard object that is its write path.
STANDARD_ALIASES: dict[str, tuple[int, int]] = {
    "TARGET_ANGLE": (0x607A, 0),
    "ACTUAL_ANGLE": (0x6064, 0),
    "VELOCITY": (0x606C, 0),
    "FAULT_CODE": (0x603F, 0),
    "SOFT_LIMIT_MIN": (0x607D, 1),
    "SOFT_LIMIT_MAX": (0x607D, 2),
    "MAX_SPEED": (0x6081, 0),
    "HEARTBEAT_TIMEOUT": (0x1016, 1),
}
#: Registers with no CANopen object at all (the heartbeat protocol replaces them).
NOT_MAPPED = ("HEARTBEAT",)

#: heliotrack fault -> CiA 402 error code (0x603F, also sent as EMCY).
FAULT_ERROR_CODES: dict[Fault, int] = {
    Fault.NONE: 0x0000,
    Fault.STALL: 0x8611,  # following error
    Fault.HARD_LIMIT: 0x8612,  # reference limit
    Fault.OVERCURRENT: 0x2310,  # continuous over current
    Fault.ENCODER: 0x7305,  # incremental sensor 1 fault
    Fault.OVERTEMPERATURE: 0x4310,  # excess temperature drive
}


@dataclass(frozen=True)
class OdEntry:
    """One object or sub-object of the dictionary.

    Attributes
    ----------
    index, subindex : int
    name : str
        CANopen parameter name.
    data_type : int
        CiA 301 data type code.
    access : str
        ``ro``, ``rw``, ``wo`` or ``const``.
    default : int or str
        Default value; may contain ``$NODEID`` (COB-IDs).
    pdo : bool
        PDO mappable.
    register : str
        Name of the Modbus register this object carries ("" when none).
    scale : float
        Engineering value = raw * scale (the register's scale).
    unit : str
        Unit of the engineering value.
    """

    index: int
    subindex: int
    name: str
    data_type: int
    access: str
    default: int | str = 0
    pdo: bool = False
    register: str = ""
    scale: float = 1.0
    unit: str = ""

    @property
    def bits(self) -> int:
        return TYPE_BITS[self.data_type]


@dataclass(frozen=True)
class OdObject:
    """A VAR (one entry, sub-index 0) or an ARRAY/RECORD (entries from sub-index 0)."""

    index: int
    name: str
    object_type: int
    entries: tuple[OdEntry, ...] = field(default_factory=tuple)


def _var(
    index: int,
    name: str,
    dtype: int,
    access: str,
    default: int | str = 0,
    pdo: bool = False,
    register: str = "",
    scale: float = 1.0,
    unit: str = "",
) -> OdObject:
    return OdObject(
        index, name, VAR, (OdEntry(index, 0, name, dtype, access, default, pdo, register, scale, unit),)
    )


def _record(
    index: int,
    name: str,
    subs: Sequence[tuple[str, int, str, int | str]],
    object_type: int = RECORD,
    highest_access: str = "ro",
) -> OdObject:
    entries = [OdEntry(index, 0, "Highest sub-index supported", UNSIGNED8, highest_access, len(subs))]
    entries += [OdEntry(index, i + 1, n, t, a, d) for i, (n, t, a, d) in enumerate(subs)]
    return OdObject(index, name, object_type, tuple(entries))


@dataclass(frozen=True)
class PdoLayout:
    """Default mapping of one PDO: (index, subindex) of each mapped object, in order."""

    number: int  # 1-based
    cob_base: int  # COB-ID = cob_base + node id
    objects: tuple[tuple[int, int], ...]


RPDOS: tuple[PdoLayout, ...] = (
    PdoLayout(1, 0x200, ((0x6040, 0), (0x607A, 0))),  # controlword + target
    PdoLayout(2, 0x300, ((0x6060, 0),)),  # modes of operation
)
TPDOS: tuple[PdoLayout, ...] = (
    PdoLayout(1, 0x180, ((0x6041, 0), (0x6064, 0))),  # statusword + actual
    PdoLayout(2, 0x280, ((0x6061, 0), (0x2107, 0), (0x2105, 0), (0x2106, 0))),
    PdoLayout(3, 0x380, ((0x606C, 0), (0x2100, 0))),  # velocity + effective target
    PdoLayout(4, 0x480, ((0x603F, 0), (0x1001, 0))),  # error code + error register
)


def mirror_index(reg: Register) -> int:
    """Manufacturer-range index of a register's mirror object."""
    return (AXIS_MIRROR_BASE if reg.per_axis else GLOBAL_MIRROR_BASE) + reg.offset


def register_objects() -> list[OdObject]:
    """The manufacturer mirror of every register (except :data:`NOT_MAPPED`)."""
    out = []
    for reg in GLOBAL_REGISTERS + AXIS_REGISTERS:
        if reg.name in NOT_MAPPED:
            continue
        access = "rw" if reg.writable and reg.name not in STANDARD_ALIASES else "ro"
        out.append(
            _var(
                mirror_index(reg),
                f"HT {reg.name}",
                _REG_TYPES[reg.type],
                access,
                0,
                pdo=True,
                register=reg.name,
                scale=reg.scale,
                unit=reg.unit,
            )
        )
    out.append(_var(AXIS_INDEX_OBJECT, "HT AXIS_INDEX", UNSIGNED8, "ro", 0))
    return out


def _pdo_objects() -> list[OdObject]:
    out = []
    for kind, layouts, com_base, map_base in (
        ("RPDO", RPDOS, 0x1400, 0x1600),
        ("TPDO", TPDOS, 0x1800, 0x1A00),
    ):
        for p in layouts:
            subs: list[tuple[str, int, str, int | str]] = [
                ("COB-ID", UNSIGNED32, "rw", f"$NODEID+0x{p.cob_base:X}"),
                ("Transmission type", UNSIGNED8, "rw", 255),
            ]
            if kind == "TPDO":
                subs += [
                    ("Inhibit time", UNSIGNED16, "rw", 0),
                    ("Compatibility entry", UNSIGNED8, "rw", 0),
                    ("Event timer", UNSIGNED16, "rw", TPDO_EVENT_TIMER_MS[p.number]),
                ]
            out.append(_record(com_base + p.number - 1, f"{kind}{p.number} communication parameter", subs))
            maps = []
            for k, (idx, sub) in enumerate(p.objects):
                bits = next(
                    e.bits for o in OBJECTS_NO_PDO for e in o.entries if (e.index, e.subindex) == (idx, sub)
                )
                maps.append((f"Mapped object {k + 1}", UNSIGNED32, "rw", (idx << 16) | (sub << 8) | bits))
            for k in range(len(p.objects), 8):
                maps.append((f"Mapped object {k + 1}", UNSIGNED32, "rw", 0))
            rec = _record(
                map_base + p.number - 1, f"{kind}{p.number} mapping parameter", maps, highest_access="rw"
            )
            # Number of mapped objects, not of sub-indices.
            first = OdEntry(rec.index, 0, "Number of mapped objects", UNSIGNED8, "rw", len(p.objects))
            out.append(OdObject(rec.index, rec.name, RECORD, (first,) + rec.entries[1:]))
    return out


def _standard_objects() -> list[OdObject]:
    s = {n: next(r for r in GLOBAL_REGISTERS + AXIS_REGISTERS if r.name == n) for n in STANDARD_ALIASES}
    return [
        _var(0x1000, "Device type", UNSIGNED32, "ro", DEVICE_TYPE),
        _var(0x1001, "Error register", UNSIGNED8, "ro", 0, pdo=True),
        _var(0x1008, "Manufacturer device name", VISIBLE_STRING, "const", "heliotrack drive"),
        OdObject(
            0x1016,
            "Consumer heartbeat time",
            ARRAY,
            (
                OdEntry(0x1016, 0, "Highest sub-index supported", UNSIGNED8, "ro", 1),
                OdEntry(
                    0x1016,
                    1,
                    "Consumer heartbeat time 1",
                    UNSIGNED32,
                    "rw",
                    (MASTER_NODE_ID << 16) | round(FACTORY["HEARTBEAT_TIMEOUT"] * 1000),
                    register="HEARTBEAT_TIMEOUT",
                    scale=0.001,
                    unit="s",
                ),
            ),
        ),
        _var(0x1017, "Producer heartbeat time", UNSIGNED16, "rw", DEFAULT_PRODUCER_HEARTBEAT_MS),
        _record(
            0x1018,
            "Identity object",
            [
                ("Vendor-ID", UNSIGNED32, "ro", VENDOR_ID),
                ("Product code", UNSIGNED32, "ro", PRODUCT_CODE),
                ("Revision number", UNSIGNED32, "ro", REVISION),
                ("Serial number", UNSIGNED32, "ro", 0),
            ],
        ),
        _var(0x603F, "Error code", UNSIGNED16, "ro", 0, pdo=True, register="FAULT_CODE"),
        _var(0x6040, "Controlword", UNSIGNED16, "rw", 0, pdo=True),
        _var(0x6041, "Statusword", UNSIGNED16, "ro", 0, pdo=True, register="STATUS"),
        # how a quick stop ends: option 6, stop and stay in QUICK STOP ACTIVE until enabled again
        # (the halt is immediate: a tracker's slew is slow), which the emulator implements
        _var(0x605A, "Quick stop option code", INTEGER16, "ro", QUICK_STOP_OPTION),
        _var(0x6060, "Modes of operation", INTEGER8, "rw", PROFILE_POSITION, pdo=True),
        _var(0x6061, "Modes of operation display", INTEGER8, "ro", PROFILE_POSITION, pdo=True),
        _var(
            0x6064,
            "Position actual value",
            INTEGER32,
            "ro",
            0,
            pdo=True,
            register="ACTUAL_ANGLE",
            scale=s["ACTUAL_ANGLE"].scale,
            unit="deg",
        ),
        _var(
            0x606C,
            "Velocity actual value",
            INTEGER32,
            "ro",
            0,
            pdo=True,
            register="VELOCITY",
            scale=s["VELOCITY"].scale,
            unit="deg/s",
        ),
        _var(
            0x607A,
            "Target position",
            INTEGER32,
            "rw",
            0,
            pdo=True,
            register="TARGET_ANGLE",
            scale=s["TARGET_ANGLE"].scale,
            unit="deg",
        ),
        OdObject(
            0x607D,
            "Software position limit",
            ARRAY,
            (
                OdEntry(0x607D, 0, "Highest sub-index supported", UNSIGNED8, "ro", 2),
                OdEntry(
                    0x607D,
                    1,
                    "Min position limit",
                    INTEGER32,
                    "rw",
                    round(FACTORY["SOFT_LIMIT_MIN"] / s["SOFT_LIMIT_MIN"].scale),
                    register="SOFT_LIMIT_MIN",
                    scale=s["SOFT_LIMIT_MIN"].scale,
                    unit="deg",
                ),
                OdEntry(
                    0x607D,
                    2,
                    "Max position limit",
                    INTEGER32,
                    "rw",
                    round(FACTORY["SOFT_LIMIT_MAX"] / s["SOFT_LIMIT_MAX"].scale),
                    register="SOFT_LIMIT_MAX",
                    scale=s["SOFT_LIMIT_MAX"].scale,
                    unit="deg",
                ),
            ),
        ),
        _var(
            0x6081,
            "Profile velocity",
            UNSIGNED32,
            "rw",
            round(FACTORY["MAX_SPEED"] / s["MAX_SPEED"].scale),
            pdo=True,
            register="MAX_SPEED",
            scale=s["MAX_SPEED"].scale,
            unit="deg/s",
        ),
        _var(0x6502, "Supported drive modes", UNSIGNED32, "ro", SUPPORTED_DRIVE_MODES),
    ]


OBJECTS_NO_PDO: tuple[OdObject, ...] = tuple(_standard_objects() + register_objects())
#: Every object of the dictionary, sorted by index.
OBJECTS: tuple[OdObject, ...] = tuple(sorted(OBJECTS_NO_PDO + tuple(_pdo_objects()), key=lambda o: o.index))
BY_INDEX: dict[int, OdObject] = {o.index: o for o in OBJECTS}


def entry(index: int, subindex: int = 0) -> OdEntry:
    """Look up an entry (KeyError names the index)."""
    try:
        return next(e for e in BY_INDEX[index].entries if e.subindex == subindex)
    except (KeyError, StopIteration):
        raise KeyError(f"no object 0x{index:04X}:{subindex:02X}") from None


def register_entry(name: str) -> OdEntry:
    """The entry a register is written/read through: the standard alias, else the mirror."""
    if name in STANDARD_ALIASES:
        return entry(*STANDARD_ALIASES[name])
    reg = next(r for r in GLOBAL_REGISTERS + AXIS_REGISTERS if r.name == name)
    return entry(mirror_index(reg))


def axis_node_id(drive_node_id: int, axis: int) -> int:
    """Node id of ``axis`` on the drive whose first node is ``drive_node_id``."""
    if not 0 <= axis < MAX_AXES:
        raise ValueError(f"axis must be 0..{MAX_AXES - 1}")
    return drive_node_id + axis


def check_node_id(node_id: int, axes: int = 1) -> None:
    """Raise ValueError unless nodes ``node_id .. node_id + axes - 1`` are valid drive ids."""
    if not 1 <= node_id or node_id + axes - 1 > MAX_NODE_ID:
        raise ValueError(
            f"node id {node_id} with {axes} axis(es) needs ids 1..{MAX_NODE_ID} (0x7F is the master's)"
        )


# -- EDS (CiA 306) --------------------------------------------------------------------------
