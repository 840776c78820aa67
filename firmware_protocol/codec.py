"""Encoders and decoders between engineering values and 16-bit register words.

Both sides (the controller's drive client and the HIL firmware) use these, so the scale,
sign and word order are defined once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from .errors import ProtocolError
from .registers import AXIS_BASE, AXIS_STRIDE, MAX_AXES, REGISTER_MAP, Register, register

_RANGES = {
    "uint16": (0, 0xFFFF),
    "int16": (-0x8000, 0x7FFF),
    "uint32": (0, 0xFFFFFFFF),
    "int32": (-0x80000000, 0x7FFFFFFF),
}


def to_raw(reg: Register, value: float) -> int:
    """Engineering value -> integer on the wire (before word splitting)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ProtocolError(f"{reg.name}: value must be finite, got {value!r}")
    raw = int(round(value / reg.scale)) if reg.scale != 1 else int(value)
    lo, hi = _RANGES[reg.type]
    if not lo <= raw <= hi:
        raise ProtocolError(
            f"{reg.name}: {value} {reg.unit} is outside the {reg.type} range "
            f"[{lo * reg.scale:g}, {hi * reg.scale:g}] {reg.unit}".rstrip()
        )
    return raw


def raw_to_words(reg: Register, raw: int) -> list[int]:
    if reg.words == 1:
        return [raw & 0xFFFF]
    raw &= 0xFFFFFFFF
    return [(raw >> 16) & 0xFFFF, raw & 0xFFFF]


def words_to_raw(reg: Register, words: Sequence[int]) -> int:
    if len(words) != reg.words:
        raise ProtocolError(f"{reg.name}: expected {reg.words} word(s), got {len(words)}")
    for w in words:
        if not 0 <= w <= 0xFFFF:
            raise ProtocolError(f"{reg.name}: word {w!r} is not 16-bit")
    raw = words[0] if reg.words == 1 else (words[0] << 16) | words[1]
    bits = 16 * reg.words
    if reg.signed and raw >= 1 << (bits - 1):
        raw -= 1 << bits
    return raw


def encode(reg: Register | str, value: float) -> list[int]:
    """Engineering value -> register words (high word first)."""
    reg = register(reg) if isinstance(reg, str) else reg
    return raw_to_words(reg, to_raw(reg, value))


def decode(reg: Register | str, words: Sequence[int]) -> float | int:
    """Register words -> engineering value (int for unscaled registers)."""
    reg = register(reg) if isinstance(reg, str) else reg
    raw = words_to_raw(reg, words)
    return raw if reg.scale == 1 else raw * reg.scale


def decode_block(words: Sequence[int], start: int, axis: int | None = None) -> dict[str, float | int]:
    """Decode every register fully contained in ``words`` read from address ``start``.

    With ``axis`` given, only that axis's per-axis registers are decoded (keyed by plain
    name); otherwise per-axis registers are keyed ``NAME[k]``.
    """
    out: dict[str, float | int] = {}
    end = start + len(words)
    for reg in REGISTER_MAP:
        axes = range(MAX_AXES) if reg.per_axis else [None]
        for k in axes:
            if axis is not None and reg.per_axis and k != axis:
                continue
            addr = reg.address(k)
            if start <= addr and addr + reg.words <= end:
                key = reg.name if (k is None or axis is not None) else f"{reg.name}[{k}]"
                out[key] = decode(reg, words[addr - start : addr - start + reg.words])
    return out


_AXIS_LAYOUT = tuple((reg, reg.offset) for reg in REGISTER_MAP if reg.per_axis)


def decode_axis(words: Sequence[int], offset: int = 0) -> dict[str, float | int]:
    """Decode one axis block (``AXIS_STRIDE`` words starting at ``words[offset]``).

    The fast path for the cyclic state read: keys are plain register names.
    """
    out: dict[str, float | int] = {}
    for reg, o in _AXIS_LAYOUT:
        i = offset + o
        out[reg.name] = decode(reg, words[i : i + reg.words])
    return out


def axis_block_address(axis: int) -> int:
    """First address of an axis's block."""
    return AXIS_BASE + axis * AXIS_STRIDE


def encode_values(values: Mapping[str, float], axis: int | None = None) -> dict[int, int]:
    """Map of register names -> values to a map of address -> word, for writes."""
    out: dict[int, int] = {}
    for name, value in values.items():
        reg = register(name)
        base = reg.address(axis if reg.per_axis else None)
        for i, w in enumerate(encode(reg, value)):
            out[base + i] = w
    return out
