"""CiA 301's rules for writing a PDO's parameters, as a device enforces them.

A master reconfigures a PDO in a fixed order: make it invalid (bit 31 of the COB-ID), set
the transmission type and timers, clear the mapping's count (sub-index 0), write the
entries, set the count, make the PDO valid again (what ``canopen``'s ``PdoMap.save`` does).
A device refuses the writes that break that order or map what it cannot send, with the
abort codes of CiA 301 (the checks and codes CANopenNode uses).  Without these the
emulator took any parameter, so a master that skipped a step, or mapped 72 bits, passed
against it and failed on a real drive.

All functions are pure: ``stored(index, subindex)`` gives the value in the object
dictionary now.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import canopen
from canopen.sdo import SdoAbortedError

ABORT_UNSUPPORTED = 0x06010000  # unsupported access to an object
ABORT_NO_OBJECT = 0x06020000  # object does not exist
ABORT_NOT_MAPPABLE = 0x06040041  # object cannot be mapped to the PDO
ABORT_PDO_LENGTH = 0x06040042  # number and length of objects exceed the PDO length
ABORT_VALUE_RANGE = 0x06090030  # invalid value for parameter

COB_INVALID = 1 << 31
COB_FRAME_29BIT = 1 << 29
_COB_ID_BITS = (1 << 29) - 1
#: CAN-IDs a PDO must not use (CiA 301 7.3.5: NMT, SYNC/EMCY, SDO, NMT error control, LSS)
_RESTRICTED = ((0x000, 0x07F), (0x101, 0x180), (0x581, 0x5FF), (0x601, 0x67F), (0x6E0, 0x6FF), (0x701, 0x7FF))
#: The data-type dummies an RPDO may map to skip bytes it does not use (index: bits)
_DUMMIES = {0x0002: 8, 0x0003: 16, 0x0004: 32, 0x0005: 8, 0x0006: 16, 0x0007: 32}
_PDO_BITS = 64

Stored = Callable[[int, int], int]


def stored_in(node: canopen.LocalNode) -> Stored:
    """``stored`` for a local node: its data store's value, else the dictionary's default."""

    def stored(index: int, subindex: int) -> int:
        var = node.object_dictionary.get_variable(index, subindex)
        assert var is not None, f"0x{index:04X}:{subindex:02X} is not in the dictionary"
        raw = node.data_store.get(index, {}).get(subindex)
        return int(var.decode_raw(raw)) if raw is not None else int(var.default or 0)

    return stored


def is_rpdo(index: int) -> bool:
    """Whether a PDO parameter object (communication or mapping) belongs to an RPDO."""
    return 0x1400 <= index < 0x1800


def check_pdo_write(
    od: canopen.ObjectDictionary, index: int, subindex: int, value: int, stored: Stored
) -> None:
    """Refuse a write of ``value`` to PDO parameter ``index:subindex`` that CiA 301 forbids.

    Raises
    ------
    SdoAbortedError
        With the abort code a device answers (see the module's constants).
    """
    if 0x1400 <= index < 0x1600 or 0x1800 <= index < 0x1A00:
        _check_communication(index, subindex, value, stored)
    elif 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00:
        _check_mapping(od, index, subindex, value, stored)


def _valid(cob_id: int) -> bool:
    return not cob_id & COB_INVALID


def _check_communication(index: int, subindex: int, value: int, stored: Stored) -> None:
    old_cob = stored(index, 1)
    if subindex == 1:
        can_id = value & _COB_ID_BITS
        if value & COB_FRAME_29BIT or can_id > 0x7FF:  # 11-bit identifiers only
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        if _valid(value):
            if _valid(old_cob) and can_id != old_cob & _COB_ID_BITS:
                raise SdoAbortedError(ABORT_VALUE_RANGE)  # the ID of a PDO in use
            if any(lo <= can_id <= hi for lo, hi in _RESTRICTED):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
    elif subindex == 2:
        # 0-240 synchronous, 254-255 event-driven; 241-251 reserved; 252-253 (RTR) not
        # supported by this device
        if 240 < value < 254:
            raise SdoAbortedError(ABORT_VALUE_RANGE)
    elif subindex == 3 and _valid(old_cob):
        raise SdoAbortedError(ABORT_VALUE_RANGE)  # inhibit time: only while the PDO is invalid


def _check_mapping(
    od: canopen.ObjectDictionary, index: int, subindex: int, value: int, stored: Stored
) -> None:
    if _valid(stored(index - 0x200, 1)):
        raise SdoAbortedError(ABORT_UNSUPPORTED)  # make the PDO invalid first
    if subindex == 0:
        mapping: Any = od[index]
        if value > len(mapping.subindices) - 1:
            raise SdoAbortedError(ABORT_PDO_LENGTH)
        bits = sum(_entry_bits(od, index, stored(index, k)) for k in range(1, value + 1))
        if bits > _PDO_BITS:
            raise SdoAbortedError(ABORT_PDO_LENGTH)
        return
    if stored(index, 0) != 0:
        raise SdoAbortedError(ABORT_UNSUPPORTED)  # set the count to 0 first
    _entry_bits(od, index, value)


def _entry_bits(od: canopen.ObjectDictionary, index: int, entry: int) -> int:
    """The length (bits) of mapping entry ``entry`` (index << 16 | subindex << 8 | bits) of
    mapping object ``index``, once checked; a zero entry maps nothing."""
    if entry == 0:
        return 0
    obj, sub, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
    rpdo = is_rpdo(index)
    if obj in _DUMMIES:
        if not rpdo or sub != 0 or bits != _DUMMIES[obj]:
            raise SdoAbortedError(ABORT_NOT_MAPPABLE)
        return bits
    if obj not in od:
        raise SdoAbortedError(ABORT_NO_OBJECT)
    o: Any = od[obj]  # canopen's types: a record or an array has sub-indices, a variable not
    var = o.subindices.get(sub) if hasattr(o, "subindices") else o if sub == 0 else None
    if var is None:
        raise SdoAbortedError(ABORT_NO_OBJECT)
    if not var.pdo_mappable or not (var.writable if rpdo else var.readable) or bits != len(var):
        raise SdoAbortedError(ABORT_NOT_MAPPABLE)
    return bits
