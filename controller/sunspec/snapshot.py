"""What the controller hands the SunSpec server, and what the server hands back.

The server never reaches into the controller: it calls a snapshot callable on every read
and delivers accepted operator writes to an ``on_override`` callback.  Angles are in
degrees at this boundary, like everywhere else in heliotrack.

Single-axis rows: model 601 has no rotation point.  Its ``Typ`` enum calls a single-axis
tracker with a horizontal axis ``Horizontal`` (``Tilted`` if the axis is tilted), and its
point descriptions say the azimuth points are "unimplemented for single axis horizontal
tracker type" while the elevation points ("degrees from horizontal") stay.  So a row's
rotation angle (pvlib ``tracker_theta``: 0 = panel flat, positive = rotated towards the
west for a north-south axis) is carried in the elevation points (``ElTrgt``, ``ElPos``,
``ElCtl``, ``GlblElCtl``), and the azimuth points read as unimplemented.  Use
:meth:`TrackerSnapshot.row` to build one without thinking about it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

TRACKER_MODES = ("TRACK", "DIFFUSE", "STOW", "MANUAL", "CALIBRATE")
PLANT_TYPES = ("dual-axis", "single-axis")

# model 601 Ctl / GlblCtl symbol names (checked against the JSON at import of encode.py)
CTL_AUTOMATIC = "Automatic"
CTL_MANUAL = "Manual"
CTL_CALIBRATE = "Calibrate"


@dataclass(frozen=True)
class TrackerSnapshot:
    """One tracker (dual-axis) or row (single-axis) as SCADA should see it.

    Parameters
    ----------
    name : str
        Shown in the block's ``Id`` point (16 bytes of UTF-8 at most).
    el_target_deg, az_target_deg : float or None
        Automatic target, degrees (elevation above the horizon; azimuth clockwise from
        north).  Single-axis: rotation in ``el_target_deg``; ``az_target_deg`` ignored.
        None = unknown, served as "unimplemented".
    el_pos_deg, az_pos_deg : float or None
        Measured position, degrees; same conventions.
    mode : str
        Controller mode, one of :data:`TRACKER_MODES`.  ``MANUAL`` reads as Ctl=Manual,
        ``CALIBRATE`` as Ctl=Calibrate, everything else as Ctl=Automatic.
    alarm_bits : int
        Model 601 ``Alm`` bits: bit 0 SetPoint, bit 1 ObsEl, bit 2 ObsAz (names from the
        JSON).  Bits the model does not define are dropped.
    manual_el_deg, manual_az_deg : float or None
        The manual-override setpoint in force (or staged), degrees.
    el_limits_deg, az_limits_deg : (float, float) or None
        Soft limits, degrees; operator writes outside them are refused (exception 3).
        None = only the protocol range (elevation/rotation [-90, 90], azimuth [0, 360)).
    single_axis : bool
        A single-axis row (made by :meth:`row`): writes to its azimuth points are refused.
    """

    name: str
    el_target_deg: float | None
    az_target_deg: float | None
    el_pos_deg: float | None
    az_pos_deg: float | None
    mode: str = "TRACK"
    alarm_bits: int = 0
    manual_el_deg: float | None = None
    manual_az_deg: float | None = None
    el_limits_deg: tuple[float, float] | None = None
    az_limits_deg: tuple[float, float] | None = None
    single_axis: bool = False  # a row (:meth:`row`): its azimuth points are unimplemented

    def __post_init__(self):
        # accept controller.modes.ControlMode members as well as their string values
        object.__setattr__(self, "mode", str(getattr(self.mode, "value", self.mode)))
        if self.mode not in TRACKER_MODES:
            raise ValueError(f"tracker {self.name!r}: mode {self.mode!r} not in {TRACKER_MODES}")

    @classmethod
    def row(
        cls,
        name: str,
        rotation_target_deg: float | None,
        rotation_deg: float | None,
        mode: str = "TRACK",
        alarm_bits: int = 0,
        manual_rotation_deg: float | None = None,
        rotation_limits_deg: tuple[float, float] | None = None,
    ) -> TrackerSnapshot:
        """A single-axis row: the rotation (pvlib ``tracker_theta``, degrees) goes in the
        elevation fields, see the module docstring."""
        return cls(
            name,
            rotation_target_deg,
            None,
            rotation_deg,
            None,
            mode,
            alarm_bits,
            manual_rotation_deg,
            None,
            rotation_limits_deg,
            None,
            single_axis=True,
        )


WEATHER_STOWS = ("", "wind", "hail", "snow")
STOW_REQUEST_KINDS = (None, "snow", "hail")
#: The ``SafetyState.request`` source of SCADA's stow requests.
SUNSPEC_SOURCE = "sunspec"


@dataclass(frozen=True)
class WeatherSnapshot:
    """The plant's weather state, for the vendor model 64601 (``docs/sunspec.md``).

    Parameters
    ----------
    stow : str
        The weather stow in force: ``"wind"``, ``"hail"``, ``"snow"`` or ``""`` (none).
        While one is, model 601 writes are refused (exception 6, device busy).
    reason : str
        Why (``"wind: gust 24.1 m/s, ..."``, ``"snow stow (sunspec)"``).
    speed_m_s, gust_m_s, mean_10min_m_s : float or None
        The anemometer's last valid reading; None: no anemometer or no reading yet.
    anemometer_lost : bool
        No valid reading for ``[wind] silent_timeout_s`` (alarms even without stowing).
    requests : tuple of (source, kind)
        Snow and hail requests in force (``("sunspec", "snow")``, ``("flag file",
        "hail")``), whether or not a higher stow outranks them.
    """

    stow: str = ""
    reason: str = ""
    speed_m_s: float | None = None
    gust_m_s: float | None = None
    mean_10min_m_s: float | None = None
    anemometer_lost: bool = False
    requests: tuple[tuple[str, str], ...] = ()

    def __post_init__(self):
        if self.stow not in WEATHER_STOWS:
            raise ValueError(f"weather stow {self.stow!r} not in {WEATHER_STOWS}")
        object.__setattr__(self, "requests", tuple(sorted((str(s), str(k)) for s, k in self.requests)))
        for source, kind in self.requests:
            if kind not in STOW_REQUEST_KINDS:
                raise ValueError(f"stow request {kind!r} of {source!r} not in {STOW_REQUEST_KINDS[1:]}")

    @property
    def sunspec_request(self) -> str | None:
        """SCADA's own request (source ``"sunspec"``): ``"snow"``, ``"hail"`` or None."""
        return dict(self.requests).get(SUNSPEC_SOURCE)


@dataclass(frozen=True)
class PlantSnapshot:
    """The whole plant at one instant.

    Parameters
    ----------
    name : str
        Controller name, model 601 ``Nam`` (16 bytes at most).
    type : str
        ``"dual-axis"`` (Typ = Dual) or ``"single-axis"`` (Typ = Horizontal, or Tilted
        when ``axis_tilt_deg`` is not 0).
    local_time : datetime
        Plant-local wall time, for ``DtLoc``, ``TmLoc`` and ``Day`` (naive or aware; it
        is printed as is, not converted).
    trackers : sequence of TrackerSnapshot
        One repeating block each, in this order (block i = tracker index i).  The count
        is fixed when the server starts.
    axis_tilt_deg : float
        Single-axis only: axis tilt, degrees; selects Horizontal vs Tilted.
    weather : WeatherSnapshot
        Weather stow, wind and alarms (vendor model 64601).
    """

    name: str
    type: str
    local_time: datetime
    trackers: tuple[TrackerSnapshot, ...] = field(default_factory=tuple)
    axis_tilt_deg: float = 0.0
    weather: WeatherSnapshot = field(default_factory=WeatherSnapshot)

    def __post_init__(self):
        if self.type not in PLANT_TYPES:
            raise ValueError(f"plant type {self.type!r} not in {PLANT_TYPES}")
        object.__setattr__(self, "trackers", tuple(self.trackers))


@dataclass(frozen=True)
class OverrideCommand:
    """An accepted SCADA write, for the controller to apply.

    Every accepted write produces one command per scope it touched, carrying the full
    staged state of that scope (not only the registers written), so a client that writes
    ``ElCtl``, ``AzCtl`` and ``Ctl`` in separate requests ends with a complete command.

    Parameters
    ----------
    tracker : int or None
        0-based tracker (repeating block) index; None = global (all trackers).
    ctl : str
        ``"Automatic"``, ``"Manual"`` or ``"Calibrate"`` (model 601 Ctl symbols).
    el_deg, az_deg : float or None
        Manual setpoint, degrees; applies when ``ctl == "Manual"``.  Single-axis:
        ``el_deg`` is the rotation and ``az_deg`` is None.  None = not set (global
        only: each tracker keeps its own).
    peer : str
        The client's IP address, for the audit log.
    """

    tracker: int | None
    ctl: str
    el_deg: float | None
    az_deg: float | None
    peer: str = ""


@dataclass(frozen=True)
class StowRequest:
    """An accepted SCADA write of the vendor model's ``StowReq``: a snow or hail stow
    requested (``kind`` ``"snow"`` or ``"hail"``) or withdrawn (None), for the controller's
    ``SafetyState.request("sunspec", kind)``.  ``peer`` as for :class:`OverrideCommand`."""

    kind: str | None
    peer: str = ""
