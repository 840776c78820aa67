"""Model 601 control registers: what SCADA may write, how a write is checked and staged.

Writable points are the model 601 points the JSON marks ``"access": "RW"`` (GlblElCtl,
GlblAzCtl, GlblCtl and per tracker ElCtl, AzCtl, Ctl).  Model 1's ``DA`` is also RW in
the JSON but is not writable here: re-addressing the device from the network is not an
operator action.

The server keeps a staged copy of each scope's control registers.  It follows the
controller (re-seeded from the snapshot whenever the snapshot's view of that scope
changes, e.g. calibration finished and the tracker went back to Automatic) and takes
operator writes in between, so a client that writes ``ElCtl``, ``AzCtl`` and ``Ctl`` in
three requests produces a complete command even if the controller applies commands only
once per cycle.
"""

from __future__ import annotations

from pymodbus.constants import ExcCodes

from .encode import INT32_UNIMPLEMENTED, ControlState, ctl_name_for_mode, decode_point, raw_to_deg
from .models import TRACKER_MODEL_ID, PointSlot, SunSpecMap
from .snapshot import OverrideCommand, PlantSnapshot, StowRequest, TrackerSnapshot
from .vendor import STOW_REQUESTS, WEATHER_MODEL_ID

Command = OverrideCommand | StowRequest

# protocol-level ranges, degrees; tighter per-tracker limits come from the snapshot
EL_RANGE_DEG = (-90.0, 90.0)  # elevation, or single-axis rotation
AZ_RANGE_DEG = (0.0, 360.0)  # [0, 360)

_ANGLE_FIELD = {"ElCtl": "el_deg", "GlblElCtl": "el_deg", "AzCtl": "az_deg", "GlblAzCtl": "az_deg"}
_CTL_POINTS = ("Ctl", "GlblCtl")


class WriteRefused(Exception):
    """A write the server answers with a Modbus exception ``code``."""

    def __init__(self, code: ExcCodes, reason: str):
        super().__init__(reason)
        self.code = code
        self.reason = reason


def _within_az(az: float, lim: tuple[float, float]) -> bool:
    # azimuth limits may extend past 0/360 (e.g. (-20, 380)): accept any equivalent angle
    return any(lim[0] <= az + k <= lim[1] for k in (-360.0, 0.0, 360.0))


def _derived(tr: TrackerSnapshot) -> tuple:
    return (ctl_name_for_mode(tr.mode), tr.manual_el_deg, tr.manual_az_deg)


class ControlTable:
    """Staged control registers for the global scope (key None) and each tracker, and the
    vendor model's stow request (in the global scope)."""

    def __init__(self, smap: SunSpecMap):
        self.map = smap
        self.writable = {
            TRACKER_MODEL_ID: frozenset(p.name for p in smap.fixed.points + smap.block.points if p.writable),
            WEATHER_MODEL_ID: frozenset(p.name for p in smap.weather.points if p.writable),
        }
        self.staged: dict[int | None, ControlState] = {
            k: ControlState() for k in [None, *range(smap.n_trackers)]
        }
        self._seen: dict[int | None, tuple] = {}
        self._seen_request: tuple[str | None] | None = None
        self._last_plant: PlantSnapshot | None = None

    # -- following the controller ----------------------------------------------------
    def refresh(self, plant: PlantSnapshot) -> None:
        """Re-seed every scope whose snapshot-derived values changed since last time.

        O(trackers); skipped when ``plant`` is the very object seen last time, so a
        snapshot callable that returns a cached object per control cycle keeps a
        1000-tracker scan (~180 requests) cheap.
        """
        if plant is self._last_plant:
            return
        self._last_plant = plant
        for i, tr in enumerate(plant.trackers):
            self._reseed(i, _derived(tr))
        # global: a field shows the trackers' common value; no consensus -> keep staged
        fields = list(zip(*(_derived(tr) for tr in plant.trackers))) or [(), (), ()]
        consensus = tuple(f[0] if f and all(v == f[0] for v in f) else None for f in fields)
        self._reseed(None, consensus)
        request = (plant.weather.sunspec_request,)
        if request != self._seen_request:
            self.staged[None].stow_request = request[0]
            self._seen_request = request

    def _reseed(self, scope: int | None, derived: tuple) -> None:
        seen = self._seen.get(scope)
        st = self.staged[scope]
        for k, attr in enumerate(("ctl", "el_deg", "az_deg")):
            if seen is None or derived[k] != seen[k]:
                if derived[k] is not None or scope is not None:
                    setattr(st, attr, derived[k])
        self._seen[scope] = derived

    # -- operator writes ---------------------------------------------------------------
    def apply_write(
        self, plant: PlantSnapshot, address: int, words: list[int], peer: str = ""
    ) -> list[Command]:
        """Check a write of ``words`` at ``address``; stage it and return the commands.

        Raises
        ------
        WriteRefused
            ILLEGAL_ADDRESS if the range is not whole writable points (or writes an
            azimuth point of a single-axis plant); ILLEGAL_VALUE for an angle outside
            the range/limits, the unimplemented sentinel, or an unknown Ctl or StowReq
            value; DEVICE_BUSY for a model 601 write while a weather stow is in force.
            Nothing is staged unless the whole write is accepted.
        """
        count = len(words)
        slots = list(self.map.slots_in(address, count))
        if not slots or slots[0].address != address or slots[-1].end != address + count:
            raise WriteRefused(
                ExcCodes.ILLEGAL_ADDRESS, f"write {address}+{count} does not cover whole points"
            )
        updates: dict[int | None, dict[str, object]] = {}
        requests: list[str | None] = []
        for slot in slots:
            point_words = words[slot.address - address : slot.end - address]
            if slot.model == WEATHER_MODEL_ID and slot.point.name in self.writable[WEATHER_MODEL_ID]:
                requests.append(self._stow_request(slot, point_words))
            else:
                attr, checked = self._check(slot, plant, point_words)
                updates.setdefault(slot.tracker, {})[attr] = checked
        if updates and plant.weather.stow:
            # an override would not move a tracker now: say so rather than accept it
            raise WriteRefused(
                ExcCodes.DEVICE_BUSY, f"weather stow in force ({plant.weather.reason or plant.weather.stow})"
            )
        commands: list[Command] = []
        for kind in requests:
            self.staged[None].stow_request = kind
            commands.append(StowRequest(kind, peer))
        for scope, fields in updates.items():
            targets = [scope] if scope is not None else [None, *range(self.map.n_trackers)]
            for t in targets:
                for attr, value in fields.items():
                    setattr(self.staged[t], attr, value)
            st = self.staged[scope]
            commands.append(OverrideCommand(scope, st.ctl, st.el_deg, st.az_deg, peer))
        return commands

    @staticmethod
    def _stow_request(slot: PointSlot, words: list[int]) -> str | None:
        """The vendor model's ``StowReq``: "snow", "hail" or None (withdrawn)."""
        raw = decode_point(slot.point, words)
        if not 0 <= raw < len(STOW_REQUESTS):
            raise WriteRefused(
                ExcCodes.ILLEGAL_VALUE, f"{slot.point.name}={raw} is not 0 (none), 1 (snow) or 2 (hail)"
            )
        return None if raw == 0 else STOW_REQUESTS[raw].lower()

    def _check(self, slot: PointSlot, plant: PlantSnapshot, words: list[int]) -> tuple[str, object]:
        p = slot.point
        if p.name not in self.writable.get(slot.model, ()):
            raise WriteRefused(ExcCodes.ILLEGAL_ADDRESS, f"{p.name} is read-only")
        raw = decode_point(p, words)
        if p.name in _CTL_POINTS:
            name = p.symbol_name(raw)
            if name is None:
                raise WriteRefused(ExcCodes.ILLEGAL_VALUE, f"{p.name}={raw} is not a model 601 Ctl value")
            return "ctl", name
        attr = _ANGLE_FIELD[p.name]
        if attr == "az_deg" and plant.type == "single-axis":
            raise WriteRefused(
                ExcCodes.ILLEGAL_ADDRESS,
                f"{p.name} is unimplemented for a single-axis plant (rotation is in the El points)",
            )
        if attr == "az_deg" and slot.tracker is not None and plant.trackers[slot.tracker].single_axis:
            raise WriteRefused(  # a row of a mixed plant: the plant's Typ is the dual-axis one
                ExcCodes.ILLEGAL_ADDRESS,
                f"{p.name} is unimplemented for a single-axis row (rotation is in the El points)",
            )
        if raw == INT32_UNIMPLEMENTED:
            raise WriteRefused(ExcCodes.ILLEGAL_VALUE, f"{p.name}: the unimplemented value is not a setpoint")
        deg = raw_to_deg(raw)
        assert deg is not None  # the unimplemented sentinel was refused above
        trackers = plant.trackers if slot.tracker is None else [plant.trackers[slot.tracker]]
        if attr == "el_deg":
            ok = EL_RANGE_DEG[0] <= deg <= EL_RANGE_DEG[1] and all(
                tr.el_limits_deg is None or tr.el_limits_deg[0] <= deg <= tr.el_limits_deg[1]
                for tr in trackers
            )
        else:
            ok = AZ_RANGE_DEG[0] <= deg < AZ_RANGE_DEG[1] and all(
                tr.az_limits_deg is None or _within_az(deg, tr.az_limits_deg) for tr in trackers
            )
        if not ok:
            raise WriteRefused(ExcCodes.ILLEGAL_VALUE, f"{p.name}={deg:g} deg is out of range")
        return attr, deg
