"""Plant snapshot -> SunSpec holding registers (and register words -> point values).

The packing of each point type and its "unimplemented" sentinel come from pysunspec2's
``sunspec2.mb`` (the same functions its client uses to unpack), so a value we write is
exactly the value a pysunspec2 client reads.  Angles are int32 scaled by ``Dgr_SF``:
with ``DGR_SF = -3`` one count is 0.001 deg and an int32 spans +-2.1 million degrees.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from importlib import metadata

from sunspec2 import mb

from .models import (
    COMMON_MODEL_ID,
    END_MODEL_ID,
    SUNS_MARKER,
    TRACKER_MODEL_ID,
    PointDef,
    PointSlot,
    SunSpecMap,
)
from .snapshot import (
    CTL_AUTOMATIC,
    CTL_CALIBRATE,
    CTL_MANUAL,
    PlantSnapshot,
    TrackerSnapshot,
    WeatherSnapshot,
)
from .vendor import ALARM_BITS, STOW_KINDS, STOW_REQUESTS, WEATHER_MODEL_ID, WIND_SF

DGR_SF = -3  # angles in milli-degrees
INT32_UNIMPLEMENTED = mb.SUNS_UNIMPL_INT32

_TYP_BY_KIND = {"dual-axis": "Dual", "single-axis-horizontal": "Horizontal", "single-axis-tilted": "Tilted"}


def package_version() -> str:
    """heliotrack's installed version, for model 1 ``Vr``."""
    try:
        return metadata.version("heliotrack")
    except metadata.PackageNotFoundError:  # running from a source tree without install
        return "0+unknown"


@dataclass(frozen=True)
class Identity:
    """Model 1 (common) contents.  Strings are truncated to the point size (UTF-8 safe)."""

    manufacturer: str = "heliotrack"  # Mn
    model: str = "tracker controller"  # Md
    options: str = ""  # Opt
    version: str = ""  # Vr; "" = the installed package version
    serial_number: str = ""  # SN
    device_address: int = 1  # DA (the Modbus unit id we answer)


def deg_to_raw(deg: float | None, sf: int = DGR_SF) -> int:
    """Degrees -> scaled int32 count; None/NaN/overflow -> the unimplemented sentinel."""
    if deg is None or not math.isfinite(deg):
        return INT32_UNIMPLEMENTED
    raw = round(deg * 10.0 ** (-sf))
    if not -(2**31) < raw < 2**31:
        return INT32_UNIMPLEMENTED
    return raw


def raw_to_deg(raw: int, sf: int = DGR_SF) -> float | None:
    """Scaled int32 count -> degrees (None for the unimplemented sentinel)."""
    if raw == INT32_UNIMPLEMENTED:
        return None
    # divide by a power of ten for negative sf: 33300 / 1000 is 33.3, 33300 * 0.001 is not
    return raw / 10.0 ** (-sf) if sf < 0 else raw * 10.0**sf


def _truncate_utf8(text: str, nbytes: int) -> str:
    # cut on a character boundary: pysunspec2 decodes strict UTF-8 and would fail on a
    # half character
    return text.encode("utf-8")[:nbytes].decode("utf-8", "ignore")


def encode_point(point: PointDef, value) -> list[int]:
    """Registers for one point value; None -> the type's unimplemented sentinel."""
    nbytes = point.size * 2
    if value is None:
        data = mb.create_unimpl_value(point.type, nbytes)
    elif point.type == "string":
        data = mb.str_to_data(_truncate_utf8(str(value), nbytes), nbytes)
    else:
        data = mb.point_type_info[point.type].to_data(value, nbytes)
    return list(struct.unpack(f">{point.size}H", data))


def decode_point(point: PointDef, words: list[int]):
    """Point value (raw, unscaled) from its registers."""
    data = struct.pack(f">{len(words)}H", *words)
    return mb.point_type_info[point.type].data_to(data)


def ctl_name_for_mode(mode: str) -> str:
    """Model 601 Ctl symbol shown for a controller mode."""
    return {"MANUAL": CTL_MANUAL, "CALIBRATE": CTL_CALIBRATE}.get(mode, CTL_AUTOMATIC)


def typ_symbol(plant: PlantSnapshot) -> str:
    """Model 601 ``Typ`` symbol name for the plant (see snapshot module docstring)."""
    if plant.type == "dual-axis":
        return _TYP_BY_KIND["dual-axis"]
    tilted = abs(plant.axis_tilt_deg) > 1e-9
    return _TYP_BY_KIND["single-axis-tilted" if tilted else "single-axis-horizontal"]


def wind_to_raw(m_s: float | None) -> int | None:
    """m/s -> uint16 counts of ``WIND_SF``; None (unimplemented) for no or a bad reading."""
    if m_s is None or not math.isfinite(m_s) or m_s < 0:
        return None
    return min(round(m_s * 10.0 ** (-WIND_SF)), 0xFFFE)  # 0xFFFF reads as unimplemented


def weather_alarms(w: WeatherSnapshot) -> int:
    """The vendor model's ``Alm`` bits (see :data:`~.vendor.ALARM_BITS`)."""
    kinds = {kind for _, kind in w.requests}
    on = {
        "WindStow": w.stow == "wind",
        "AnemometerLost": w.anemometer_lost,
        "HailStow": "hail" in kinds,
        "SnowStow": "snow" in kinds,
        "StowRequested": w.sunspec_request is not None,
    }
    return sum(1 << i for i, name in enumerate(ALARM_BITS) if on[name])


@dataclass
class ControlState:
    """Contents of one scope's control registers (Ctl, ElCtl, AzCtl), in engineering
    units: ``ctl`` a Ctl symbol name, angles in degrees or None.  The global scope also
    holds the vendor model's ``StowReq`` (``"snow"``, ``"hail"`` or None)."""

    ctl: str = CTL_AUTOMATIC
    el_deg: float | None = None
    az_deg: float | None = None
    stow_request: str | None = None


class Encoder:
    """Renders register ranges of a :class:`SunSpecMap` from a plant snapshot.

    Only the points overlapping the requested range are encoded, so a client reading a
    1000-tracker model in 125-register chunks costs 1000 trackers' worth of packing per
    full scan, not per request.
    """

    def __init__(self, smap: SunSpecMap, identity: Identity = Identity()):
        self.map = smap
        self.identity = identity
        self.version = identity.version or package_version()
        fixed = smap.fixed
        self._alarm_mask = sum(1 << v for _, v in smap.block.point("Alm").symbols)
        # fail at start, not at the first read, if the JSON ever renames a symbol we use
        for name in (CTL_AUTOMATIC, CTL_MANUAL, CTL_CALIBRATE):
            fixed.point("GlblCtl").symbol_value(name)
            smap.block.point("Ctl").symbol_value(name)
        for name in _TYP_BY_KIND.values():
            fixed.point("Typ").symbol_value(name)

    def alarm_word(self, bits: int) -> int:
        return int(bits) & self._alarm_mask

    def registers(
        self, plant: PlantSnapshot, controls: dict[int | None, ControlState], address: int, count: int
    ) -> list[int]:
        """Registers ``[address, address + count)``.

        Parameters
        ----------
        plant : PlantSnapshot
            Current state; ``len(plant.trackers)`` must equal the map's tracker count.
        controls : dict
            Control registers per scope (None = global, i = tracker i).
        """
        m = self.map
        if len(plant.trackers) != m.n_trackers:
            raise ValueError(
                f"snapshot has {len(plant.trackers)} trackers, the served map "
                f"{m.n_trackers}; restart the server to change the count"
            )
        out = [0] * count
        end = address + count

        def put(start: int, words: list[int]) -> None:
            for k, w in enumerate(words):
                a = start + k
                if address <= a < end:
                    out[a - address] = w

        put(m.base_address, list(SUNS_MARKER))
        put(m.end_address, [END_MODEL_ID, 0])
        for slot in m.slots_in(address, count):
            put(slot.address, encode_point(slot.point, self._value(slot, plant, controls)))
        return out

    # -- point values ----------------------------------------------------------------
    def _value(self, slot: PointSlot, plant: PlantSnapshot, controls: dict[int | None, ControlState]):
        name = slot.point.name
        if slot.model == COMMON_MODEL_ID:
            return self._common_value(name)
        if slot.model == WEATHER_MODEL_ID:
            return self._weather_value(name, plant.weather, controls[None])
        if slot.tracker is None:
            return self._fixed_value(slot.point, plant, controls[None])
        return self._tracker_value(slot.point, plant, plant.trackers[slot.tracker], controls[slot.tracker])

    def _common_value(self, name: str):
        ident = self.identity
        return {
            "ID": COMMON_MODEL_ID,
            "L": self.map.common_length,
            "Mn": ident.manufacturer,
            "Md": ident.model,
            "Opt": ident.options,
            "Vr": self.version,
            "SN": ident.serial_number,
            "DA": ident.device_address,
            "Pad": None,
        }[name]

    def _weather_value(self, name: str, w: WeatherSnapshot, ctl: ControlState):
        return {
            "ID": WEATHER_MODEL_ID,
            "L": self.map.weather_model_length,
            "Stow": STOW_KINDS.index(w.stow.upper() or "NONE"),
            "Alm": weather_alarms(w),
            "WindSpd": wind_to_raw(w.speed_m_s),
            "WindGst": wind_to_raw(w.gust_m_s),
            "WindAvg": wind_to_raw(w.mean_10min_m_s),
            "StowReq": STOW_REQUESTS.index((ctl.stow_request or "none").upper()),
            "Rsn": w.reason,
            "Wind_SF": WIND_SF,
        }.get(name)

    def _angle(
        self, plant: PlantSnapshot, axis: str, deg: float | None, tr: TrackerSnapshot | None = None
    ) -> int:
        # single-axis: the azimuth points are unimplemented (model 601 descriptions), for
        # a single-axis plant and for a row of a mixed one (whose Typ is Dual)
        if axis == "az" and (plant.type == "single-axis" or (tr is not None and tr.single_axis)):
            return INT32_UNIMPLEMENTED
        return deg_to_raw(deg)

    def _fixed_value(self, point: PointDef, plant: PlantSnapshot, ctl: ControlState):
        name = point.name
        t = plant.local_time
        if name == "ID":
            return TRACKER_MODEL_ID
        if name == "L":
            return self.map.tracker_model_length
        if name == "Nam":
            return plant.name
        if name == "Typ":
            return point.symbol_value(typ_symbol(plant))
        if name == "DtLoc":
            return t.strftime("%Y%m%d")
        if name == "TmLoc":
            return t.strftime("%H%M%S")
        if name == "Day":
            return t.timetuple().tm_yday
        if name == "GlblElCtl":
            return self._angle(plant, "el", ctl.el_deg)
        if name == "GlblAzCtl":
            return self._angle(plant, "az", ctl.az_deg)
        if name == "GlblCtl":
            return point.symbol_value(ctl.ctl)
        if name == "GlblAlm":
            word = 0
            for tr in plant.trackers:
                word |= tr.alarm_bits
            return self.alarm_word(word)
        if name == "Dgr_SF":
            return DGR_SF
        if name == "N":
            return self.map.n_trackers
        return None  # a point added to the JSON later: served as unimplemented

    def _tracker_value(self, point: PointDef, plant: PlantSnapshot, tr: TrackerSnapshot, ctl: ControlState):
        name = point.name
        if name == "Id":
            return tr.name
        if name == "ElTrgt":
            return self._angle(plant, "el", tr.el_target_deg, tr)
        if name == "AzTrgt":
            return self._angle(plant, "az", tr.az_target_deg, tr)
        if name == "ElPos":
            return self._angle(plant, "el", tr.el_pos_deg, tr)
        if name == "AzPos":
            return self._angle(plant, "az", tr.az_pos_deg, tr)
        if name == "ElCtl":
            return self._angle(plant, "el", ctl.el_deg, tr)
        if name == "AzCtl":
            return self._angle(plant, "az", ctl.az_deg, tr)
        if name == "Ctl":
            return point.symbol_value(ctl.ctl)
        if name == "Alm":
            return self.alarm_word(tr.alarm_bits)
        return None
