"""The SunSpec register map served northbound: marker, model 1, model 601, end model.

Point names, sizes, types, scale-factor links, access and enum symbols come from the JSON
model definitions shipped with pysunspec2 (``sunspec2/models/json/model_N.json``), the
same files a SCADA client built on pysunspec2 uses to decode the registers; nothing here
hand-types an offset.  The layout::

    40000  "SunS" marker (2 registers)
    40002  model 1 (common): ID, L = 66, Mn, Md, Opt, Vr, SN, DA, Pad
    40070  model 601 (tracker controller): ID, L = 26 + 22 N, 26 fixed registers,
           then N repeating "tracker" blocks of 22 registers
    ...    end model: ID = 0xFFFF, L = 0

Addresses are the 0-based protocol addresses that appear in the request PDU (pysunspec2
reads the marker at address 40000).
"""

from __future__ import annotations

import bisect
import json
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from importlib import resources

SUNSPEC_BASE_ADDRESS = 40000
SUNS_MARKER = (0x5375, 0x6E53)  # "SunS", big-endian ASCII in two registers
END_MODEL_ID = 0xFFFF
COMMON_MODEL_ID = 1
TRACKER_MODEL_ID = 601
TRACKER_GROUP = "tracker"  # name of model 601's repeating group in the JSON
MAX_ADDRESS = 0xFFFF  # a Modbus address is 16 bits


@cache
def model_definition(model_id: int) -> dict:
    """The pysunspec2 JSON definition of a SunSpec model, as a dict.

    Read from the installed ``sunspec2`` package (a runtime dependency) rather than
    copied, so the map and the clients decoding it cannot disagree.
    """
    path = resources.files("sunspec2") / "models" / "json" / f"model_{model_id}.json"
    with path.open("r", encoding="utf-8") as f:
        return json.load(f)


@dataclass(frozen=True)
class PointDef:
    """One point of a model group, as the JSON defines it.

    ``offset`` is in registers from the start of its group (for the top-level group the
    model's ``ID`` point is at offset 0; for a repeating block its first point is at 0).
    """

    name: str
    type: str
    size: int  # registers
    offset: int  # registers from the start of the group
    sf: str | None = None  # name of the scale-factor point, if scaled
    access: str = "R"  # "R" or "RW"
    units: str | None = None
    symbols: tuple[tuple[str, int], ...] = ()
    value: int | None = None  # fixed value (model ID)

    @property
    def writable(self) -> bool:
        return self.access == "RW"

    def symbol_value(self, name: str) -> int:
        """Value of an enum/bitfield symbol by its JSON name."""
        for sym, val in self.symbols:
            if sym == name:
                return val
        raise KeyError(f"{self.name} has no symbol {name!r}")

    def symbol_name(self, value: int) -> str | None:
        for sym, val in self.symbols:
            if val == value:
                return sym
        return None


def _points(group: dict) -> tuple[PointDef, ...]:
    out, offset = [], 0
    for p in group.get("points", ()):
        out.append(
            PointDef(
                name=p["name"],
                type=p["type"],
                size=int(p["size"]),
                offset=offset,
                sf=p.get("sf"),
                access=p.get("access", "R"),
                units=p.get("units"),
                symbols=tuple((s["name"], int(s["value"])) for s in p.get("symbols", ())),
                value=p.get("value"),
            )
        )
        offset += int(p["size"])
    return tuple(out)


@dataclass(frozen=True)
class GroupDef:
    name: str
    points: tuple[PointDef, ...]

    @property
    def length(self) -> int:
        return sum(p.size for p in self.points)

    def point(self, name: str) -> PointDef:
        for p in self.points:
            if p.name == name:
                return p
        raise KeyError(f"group {self.name} has no point {name!r}")


@cache
def common_group() -> GroupDef:
    """Model 1 (common) top-level group, ID and L included."""
    d = model_definition(COMMON_MODEL_ID)["group"]
    return GroupDef(d["name"], _points(d))


@cache
def tracker_controller_groups() -> tuple[GroupDef, GroupDef]:
    """Model 601: (fixed top-level group incl. ID and L, repeating tracker block)."""
    d = model_definition(TRACKER_MODEL_ID)["group"]
    rep = [g for g in d.get("groups", ()) if g["name"] == TRACKER_GROUP]
    if len(rep) != 1:
        raise RuntimeError("sunspec2's model_601.json has no single 'tracker' group")
    return GroupDef(d["name"], _points(d)), GroupDef(rep[0]["name"], _points(rep[0]))


@dataclass(frozen=True)
class PointSlot:
    """A point placed at an absolute address.

    ``model`` is 1 or 601 (0 for the marker and end model, which are not points of a
    JSON model); ``tracker`` is the 0-based repeating-block index, None for fixed points.
    """

    address: int
    point: PointDef
    model: int
    tracker: int | None = None

    @property
    def end(self) -> int:
        return self.address + self.point.size


class SunSpecMap:
    """Absolute addresses of every point for a plant of ``n_trackers`` trackers.

    Parameters
    ----------
    n_trackers : int
        Number of repeating blocks in model 601 (the ``N`` point).
    base_address : int
        Address of the ``SunS`` marker; 40000 is the first address SunSpec clients probe.
    """

    def __init__(self, n_trackers: int, base_address: int = SUNSPEC_BASE_ADDRESS):
        self.n_trackers = int(n_trackers)
        self.base_address = int(base_address)
        self.common = common_group()
        self.fixed, self.block = tracker_controller_groups()
        self.common_address = self.base_address + 2
        # L does not count the ID and L registers themselves
        self.common_length = self.common.length - 2
        self.tracker_model_address = self.common_address + 2 + self.common_length
        self.tracker_model_length = self.fixed.length - 2 + self.n_trackers * self.block.length
        self.end_address = self.tracker_model_address + 2 + self.tracker_model_length
        self.size = self.end_address + 2 - self.base_address
        if self.n_trackers < 0 or self.end_address + 2 > MAX_ADDRESS + 1:
            n_max = (
                MAX_ADDRESS + 1 - 2 - (self.tracker_model_address + self.fixed.length)
            ) // self.block.length
            raise ValueError(
                f"model 601 with {n_trackers} trackers does not fit below address "
                f"65536 at base {base_address}: at most {n_max}"
            )
        slots: list[PointSlot] = []
        for p in self.common.points:
            slots.append(PointSlot(self.common_address + p.offset, p, COMMON_MODEL_ID))
        for p in self.fixed.points:
            slots.append(PointSlot(self.tracker_model_address + p.offset, p, TRACKER_MODEL_ID))
        for i in range(self.n_trackers):
            start = self.block_address(i)
            for p in self.block.points:
                slots.append(PointSlot(start + p.offset, p, TRACKER_MODEL_ID, i))
        self.slots: tuple[PointSlot, ...] = tuple(slots)
        self._starts = [s.address for s in self.slots]
        self._by_name = {(s.model, s.tracker, s.point.name): s for s in self.slots}

    def block_address(self, tracker: int) -> int:
        """Address of the first register of repeating block ``tracker`` (0-based)."""
        return self.tracker_model_address + self.fixed.length + tracker * self.block.length

    def slot(self, name: str, tracker: int | None = None, model: int = TRACKER_MODEL_ID) -> PointSlot:
        """The placed point called ``name`` (of tracker ``tracker``, or fixed if None)."""
        try:
            return self._by_name[(model, tracker, name)]
        except KeyError:
            raise KeyError(f"no point {name!r} for model {model} tracker {tracker}") from None

    def slots_in(self, address: int, count: int) -> Iterator[PointSlot]:
        """Points overlapping registers ``[address, address + count)``, in address order."""
        i = max(bisect.bisect_right(self._starts, address) - 1, 0)
        stop = address + count
        while i < len(self.slots) and self.slots[i].address < stop:
            if self.slots[i].end > address:
                yield self.slots[i]
            i += 1
