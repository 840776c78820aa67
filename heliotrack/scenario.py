"""A scenario file: a plant configuration plus the ``[hil]`` table describing the emulated
world (sky, drive mechanics, camera), read by the one schema validator."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any, Literal

from controller.config import Config, load_config, parse_config
from controller.schema import Where, setting
from controller.timestamps import parse_timestamp
from hil.drive import AxisParams

from .fault_kinds import (
    FAULT_DEFAULTS,
    FAULT_KINDS,
    TRACKER_FAULTS,
    WIRE_FAULTS,
    EventFault,
    TimedFault,
    check_magnitude,
)

SkyKind = Literal["clear", "overcast", "partly-cloudy"]
WindKind = Literal["calm", "gusty", "storm"]


@dataclass(frozen=True, kw_only=True)
class HilDrive:
    """Mechanics of every emulated drive axis."""

    max_speed_dps: float = setting(1.0, doc="Top speed.", unit="deg/s", ge=0.01, le=10)
    accel_dps2: float = setting(2.0, doc="Acceleration.", unit="deg/s^2", ge=0.01, le=100)
    backlash_deg: float = setting(0.05, doc="Gear backlash.", unit="deg", ge=0, le=2)
    encoder_resolution_deg: float = setting(0.01, doc="Output-side encoder step.", unit="deg", ge=0, le=1)
    deadband_deg: float = setting(0.02, doc="Position-loop deadband.", unit="deg", ge=0, le=1)

    def axis_kwargs(self) -> dict[str, float]:
        """Keyword arguments of :class:`hil.drive.AxisParams`."""
        return dict(
            max_speed=self.max_speed_dps,
            accel=self.accel_dps2,
            backlash=self.backlash_deg,
            encoder_resolution=self.encoder_resolution_deg,
            deadband=self.deadband_deg,
        )


@dataclass(frozen=True, kw_only=True)
class HilCamera:
    """The world's hotspot camera (``control.sun_source = "hotspot"``)."""

    profile: Literal["seed", "recommended"] = setting(
        "recommended", doc="Camera profile: the paper's, or the recommended one."
    )
    noise: bool = setting(True, doc="Shot and read noise (and JPEG for the seed camera).")
    tilt_deg: float = setting(
        0.3,
        doc="Base not level by this much: the installation the shipped bundles were calibrated on.",
        unit="deg",
        ge=0,
        le=10,
    )


@dataclass(frozen=True, kw_only=True)
class HilSkyCamera:
    """The world's fisheye sky camera (``control.sun_source = "fisheye"`` or ``"fused"``),
    rendered by ``hil/skycam``; the defaults are the installation the shipped bundle
    ``config/calibration/fisheye-seed.toml`` was calibrated on."""

    profile: Literal["seed", "hd"] = setting(
        "seed",
        doc="Camera: the paper's 640 x 480 USB camera (JPEG q90), or a 1280 x 960 one "
        "(which needs a calibration bundle of its own).",
    )
    noise: bool = setting(True, doc="Shot and read noise (and JPEG for the seed camera).")
    yaw_deg: float = setting(17.0, doc="Heading: turned about its optical axis.", unit="deg", ge=-360, le=360)
    tilt_deg: float = setting(0.8, doc="Base not level by this much.", unit="deg", ge=0, le=10)
    tilt_azimuth_deg: float = setting(
        120.0, doc="Towards this azimuth (clockwise from north).", unit="deg", ge=0, le=360
    )
    clouds: bool = setting(
        True,
        doc="Draw a procedural cloud layer on cloudy days (the sun's own visibility always "
        "follows the scenario's sky, as for the hotspot camera).",
    )


@dataclass(frozen=True, kw_only=True)
class HilStorm:
    """A storm in the scenario: the mean wind ramps up, holds its peak, ramps down."""

    start: str = setting(doc="When the ramp starts (a time with a zone).", example="2024-03-20T11:00:00Z")
    peak_m_s: float = setting(
        19.0, doc="Peak 10-min mean wind (3-s gusts run about 1.4 x higher).", unit="m/s", ge=1, le=60
    )
    ramp_s: float = setting(1800.0, doc="Ramp up (and down) time.", unit="s", ge=1, le=86400)
    hold_s: float = setting(3600.0, doc="Time at the peak.", unit="s", ge=0, le=864000)

    def __schema_check__(self, at: Where) -> HilStorm:
        from controller.errors import InputError

        try:
            parse_timestamp(self.start, "start", require_zone=True)
        except InputError as exc:
            raise at.child("start").error(
                "a time with a zone, e.g. 2024-03-20T11:00:00Z", self.start
            ) from exc
        return self


@dataclass(frozen=True, kw_only=True)
class HilWind:
    """The world's wind (read by the emulated anemometer of ``[wind]``)."""

    days: WindKind | tuple[WindKind, ...] = setting(
        "calm",
        doc="Wind of each day, repeated cyclically; a storm day has a storm from 13:00 after its start.",
    )
    storms: tuple[HilStorm, ...] = setting((), doc="Storms at given times.")
    seed: int = setting(0, doc="Random seed of the turbulence.", ge=0)

    @property
    def kinds(self) -> tuple[str, ...]:
        return (self.days,) if isinstance(self.days, str) else self.days

    def __schema_check__(self, at: Where) -> HilWind:
        if not self.kinds:  # as for hil.sky: an empty cycle has no day to repeat
            raise at.child("days").error("at least one wind kind", [])
        return self

    def script(self, t0: float):
        """The :class:`hil.wind.WindScript` of this table, days counted from ``t0``."""
        from hil.wind import Storm, WindScript

        storms = tuple(
            Storm(parse_timestamp(s.start, "storm start", require_zone=True), s.peak_m_s, s.ramp_s, s.hold_s)
            for s in self.storms
        )
        return WindScript(t0, self.kinds, storms, seed=self.seed)


@dataclass(frozen=True, kw_only=True)
class HilWireRates:
    """Probability of each wire fault per transaction (each reply of a Modbus device, each
    CAN frame), on every link of its kind."""

    modbus_timeout: float = setting(0.0, doc="No reply (RTU and TCP).", ge=0, le=1)
    crc_error: float = setting(0.0, doc="Reply with a bad CRC (RTU).", ge=0, le=1)
    garbled_reply: float = setting(
        0.0, doc="Reply damaged by line noise (RTU), or with a damaged header (TCP).", ge=0, le=1
    )
    split_reply: float = setting(0.0, doc="Reply in two writes with a gap.", ge=0, le=1)
    late_reply: float = setting(0.0, doc="Reply after the link's timeout.", ge=0, le=1)
    wrong_id_reply: float = setting(0.0, doc="Reply from another slave or unit id.", ge=0, le=1)
    can_frame_lost: float = setting(0.0, doc="A CAN frame lost (either way), per frame.", ge=0, le=1)

    def wire_rates(self) -> dict[str, float]:
        """The Modbus wire-fault probabilities by kind."""
        return {k: getattr(self, k) for k in WIRE_FAULTS}


@dataclass(frozen=True, kw_only=True)
class HilFaultRate:
    """A timed fault at random: a Poisson process over the run, each occurrence on a
    target drawn at random among those it can hit."""

    type: TimedFault = setting(doc="The fault (see docs/faults.md).")
    per_hour: float = setting(doc="Mean occurrences per hour, over the whole plant.", ge=0, le=3600)
    duration_s: tuple[float, float] | None = setting(
        None, doc="Duration range [min, max], drawn uniformly (none: the fault's default).", unit="s", ge=0
    )
    magnitude: tuple[float, float] | None = setting(
        None,
        doc="Magnitude range [min, max] (wall_clock_step: s, encoder_glitch: deg, both "
        "either sign; *_out_of_range: the reading); none: the fault's default.",
    )

    def __schema_check__(self, at: Where) -> HilFaultRate:
        for key in ("duration_s", "magnitude"):
            r = getattr(self, key)
            if r is not None and not r[0] <= r[1]:
                raise at.child(key).error("[min, max] with min <= max", list(r))
        if self.magnitude is not None:
            check_magnitude(at.child("magnitude"), self.type, self.magnitude)
        return self

    def durations(self) -> tuple[float, float]:
        return self.duration_s or FAULT_DEFAULTS[self.type][0]

    def magnitudes(self) -> tuple[float, float]:
        return self.magnitude or FAULT_DEFAULTS[self.type][1]


@dataclass(frozen=True, kw_only=True)
class HilFaultEvent:
    """A fault at a given time."""

    type: EventFault = setting(doc="The fault (a wire fault hits every reply of its target while it lasts).")
    at: str = setting(doc="When it starts (a time with a zone).", example="2024-03-20T10:00:00Z")
    duration_s: float = setting(60.0, doc="How long it lasts.", unit="s", ge=0, le=864000)
    target: str = setting(
        "",
        doc='What it hits: a tracker or link name, "pyranometer", "anemometer", "camera" '
        "(empty: drawn at random among the fault's possible targets).",
    )
    magnitude: float | None = setting(
        None, doc="The fault's magnitude (see `magnitude` above; none: drawn from the default range)."
    )

    def __schema_check__(self, at: Where) -> HilFaultEvent:
        from controller.errors import InputError

        try:
            parse_timestamp(self.at, "at", require_zone=True)
        except InputError as exc:
            raise at.child("at").error("a time with a zone, e.g. 2024-03-20T10:00:00Z", self.at) from exc
        if self.magnitude is not None:
            check_magnitude(at.child("magnitude"), self.type, (self.magnitude,))
        return self

    @property
    def start(self) -> float:
        """POSIX s."""
        return parse_timestamp(self.at, "at", require_zone=True)


@dataclass(frozen=True, kw_only=True)
class HilFaults:
    """Faults injected in the world, at random rates and at given times (docs/faults.md)."""

    seed: int = setting(0, doc="Random seed of the faults (what, when, where).", ge=0)
    per_transaction: HilWireRates = setting(default_factory=HilWireRates, doc="Wire faults.")
    random: tuple[HilFaultRate, ...] = setting((), doc="Timed faults at random.")
    events: tuple[HilFaultEvent, ...] = setting((), doc="Faults at given times.")

    @property
    def enabled(self) -> bool:
        """Any fault at all (the world then adds its fault hooks)."""
        w = self.per_transaction
        return bool(
            self.events
            or any(r.per_hour > 0 for r in self.random)
            or any(getattr(w, k) > 0 for k in (*WIRE_FAULTS, "can_frame_lost"))
        )


@dataclass(frozen=True, kw_only=True)
class HilMountOffset:
    """A row whose panel sits off its drive's encoder (a mounting or encoder offset): the
    drive reports and holds its shaft, the panel (and its camera, and the pointing error's
    truth) is this much further along each axis."""

    tracker: str = setting(doc="The tracker's name.", nonempty=True)
    offset_deg: tuple[float, ...] = setting(
        (),
        doc="Per axis (dual-axis: [azimuth, elevation]; single-axis: [rotation]), panel minus shaft "
        "(empty: none).",
        unit="deg",
        ge=-10,
        le=10,
    )
    camera_deg: tuple[float, float, float] = setting(
        (0.0, 0.0, 0.0),
        doc="The panel camera's rotation on its panel, a rotation vector in the panel's frame "
        "(x across the panel towards increasing azimuth or rotation, z its normal, y = z x x): "
        "[0, 1, 0] turns the camera's axis 1 deg towards +x (a row's rotation error of 1 deg "
        "that the loop cannot see without the lens bundle's [mount]; [0, 0, 180]: the camera "
        "upside down).",
        unit="deg",
        ge=-180,
        le=180,
    )


@dataclass(frozen=True, kw_only=True)
class HilSunGap:
    """A stretch when clouds hide the sun from every camera (beam transmittance 0)."""

    start: str = setting(doc="When it starts (a time with a zone).", example="2024-03-20T10:00:00Z")
    duration_s: float = setting(7200.0, doc="How long it lasts.", unit="s", ge=0, le=864000)

    def __schema_check__(self, at: Where) -> HilSunGap:
        from controller.errors import InputError

        try:
            parse_timestamp(self.start, "start", require_zone=True)
        except InputError as exc:
            raise at.child("start").error(
                "a time with a zone, e.g. 2024-03-20T10:00:00Z", self.start
            ) from exc
        return self

    def covers(self, t: float) -> bool:
        t0 = parse_timestamp(self.start, "start", require_zone=True)
        return t0 <= t < t0 + self.duration_s


@dataclass(frozen=True, kw_only=True)
class HilReflection:
    """A sun-sized specular reflection fixed in the sky (a window, a neighbour's glass), seen
    by every panel camera, lit whatever the clouds do."""

    azimuth_deg: float = setting(doc="Its azimuth, clockwise from north.", unit="deg", ge=0, lt=360)
    elevation_deg: float = setting(doc="Its elevation above the horizon.", unit="deg", ge=-10, le=90)
    strength: float = setting(1.0, doc="Its brightness relative to the sun's glare.", gt=0, le=1)


@dataclass(frozen=True, kw_only=True)
class HilPanelCamera:
    """The cameras on the panels (``[closedloop]``): the paper's fisheye, looking along the
    panel's normal, rendered at a fraction of its 640 x 480 pixels."""

    scale: float = setting(0.5, doc="Pixels per side relative to 640 x 480 (0.5: 320 x 240).", gt=0.1, le=2)
    noise: bool = setting(True, doc="Shot and read noise, and JPEG q90.")
    clouds: bool = setting(
        True,
        doc="Draw the sky camera's procedural cloud layer on cloudy days (sunlit edges, "
        "thin cloud over the sun); the sun's own visibility follows the scenario's sky.",
    )
    reflections: tuple[HilReflection, ...] = setting(
        (), doc="Sun-sized reflections every panel camera sees (distractors)."
    )


@dataclass(frozen=True, kw_only=True)
class HilConfig:
    """The emulated world.  Each day runs from local mean midnight (UTC - longitude/15 h)."""

    start: date = setting(date(2024, 3, 20), doc="First simulated day.")
    sky: SkyKind | tuple[SkyKind, ...] = setting(
        "clear", doc="Sky regime, or a list: one per day, repeated cyclically."
    )
    seed: int = setting(0, doc="Random seed of the sky and the sensors.", ge=0)
    linke_turbidity: float = setting(3.0, doc="Clear-sky Linke turbidity.", ge=1, le=8)
    substeps: int = setting(
        4, doc="Truth samples per control period for the pointing-error and energy figures.", ge=1, le=60
    )
    drive: HilDrive = setting(default_factory=HilDrive, doc="Drive mechanics.")
    camera: HilCamera = setting(default_factory=HilCamera, doc="Hotspot camera.")
    skycam: HilSkyCamera = setting(default_factory=HilSkyCamera, doc="Fisheye sky camera.")
    wind: HilWind = setting(default_factory=HilWind, doc="Wind.")
    faults: HilFaults = setting(default_factory=HilFaults, doc="Fault injection.")
    mount_offsets: tuple[HilMountOffset, ...] = setting(
        (), doc="Rows whose panel sits off its encoder, or whose panel camera sits off the panel's normal."
    )
    sun_gaps: tuple[HilSunGap, ...] = setting((), doc="Stretches when clouds hide the sun from the cameras.")
    panel_camera: HilPanelCamera = setting(default_factory=HilPanelCamera, doc="Cameras on the panels.")

    @property
    def skies(self) -> tuple[str, ...]:
        """The sky regime of each day of the cycle."""
        return (self.sky,) if isinstance(self.sky, str) else self.sky

    def sun_hidden(self, t: float) -> bool:
        """A ``sun_gaps`` entry hides the sun at POSIX ``t``."""
        return any(g.covers(t) for g in self.sun_gaps)

    def mount_offset(self, tracker: str, axes: int) -> list[float]:
        """The tracker's mounting offset per axis (deg; zeros when none)."""
        for m in self.mount_offsets:
            if m.tracker == tracker and m.offset_deg:
                return [float(x) for x in m.offset_deg]
        return [0.0] * axes

    def camera_mount(self, tracker: str) -> tuple[float, float, float]:
        """The tracker's panel camera's rotation on its panel (rotation vector, deg)."""
        for m in self.mount_offsets:
            if m.tracker == tracker:
                return m.camera_deg
        return (0.0, 0.0, 0.0)

    def __schema_check__(self, at: Where) -> HilConfig:
        from controller.timestamps import YEARS

        if not YEARS[0] <= self.start.year <= YEARS[1]:
            raise at.child("start").error(f"a day in the years {YEARS[0]}-{YEARS[1]}", self.start.isoformat())
        if not isinstance(self.sky, str) and not self.sky:
            raise at.child("sky").error("at least one sky kind", list(self.sky))
        return self


@dataclass(frozen=True, kw_only=True)
class ScenarioConfig(Config):
    """A plant configuration run by the simulator: the plant, and the world around it."""

    hil: HilConfig = setting(default_factory=HilConfig, doc="The emulated world.")

    def __schema_check__(self, at: Where) -> ScenarioConfig:
        c = super().__schema_check__(at)
        assert isinstance(c, ScenarioConfig)
        targets = fault_targets(c)
        for i, ev in enumerate(c.hil.faults.events):
            if ev.target and ev.target not in targets.get(ev.type, ()):
                here = at.child("hil").child("faults").child("events").item(i).child("target")
                known = ", ".join(targets.get(ev.type, ())) or "nothing in this plant"
                raise here.error(f"something a {ev.type} fault can hit ({known})", ev.target)
        axes = {tr.name: tr.axes for tr in c.trackers}
        for i, m in enumerate(c.hil.mount_offsets):
            here = at.child("hil").child("mount_offsets").item(i)
            if m.tracker not in axes:
                raise here.child("tracker").error(f"a tracker name ({', '.join(axes)})", m.tracker)
            if m.offset_deg and len(m.offset_deg) != axes[m.tracker]:
                raise here.child("offset_deg").error(
                    f"{axes[m.tracker]} value(s), one per axis", list(m.offset_deg)
                )
        return c


def fault_targets(config: Config) -> dict[str, tuple[str, ...]]:
    """What each fault kind can hit in ``config``: tracker names, link names, sensors."""
    kinds = {link.name: link.kind for link in config.links}
    trackers = tuple(tr.name for tr in config.trackers)
    modbus = tuple(n for n, k in kinds.items() if k.startswith("modbus"))
    can = tuple(n for n, k in kinds.items() if k == "canopen")
    modbus_trackers = tuple(tr.name for tr in config.trackers if kinds.get(tr.link, "").startswith("modbus"))
    sensors = (("pyranometer",) if config.pyranometer is not None else ()) + (
        ("anemometer",) if config.wind is not None else ()
    )
    camera = ("camera",) if config.control.sun_source != "ephemeris" else ()  # fused: the hotspot's
    out: dict[str, tuple[str, ...]] = {}
    for k in TRACKER_FAULTS:
        out[k] = trackers
    for k in ("can_error_passive", "can_bus_off"):
        out[k] = can
    for k in WIRE_FAULTS:
        out[k] = modbus + modbus_trackers + sensors
    for sensor in ("pyranometer", "anemometer"):
        for k in ("out_of_range", "frozen", "nan"):
            out[f"{sensor}_{k}"] = (sensor,) if sensor in sensors else ()
    for k in ("black", "saturated", "truncated", "wrong_size", "missing"):
        out[f"camera_{k}"] = camera
    out["wall_clock_step"] = ("plant",)
    return out


def load_scenario(path: str | Path) -> ScenarioConfig:
    """Read and validate a scenario file."""
    return load_config(path, ScenarioConfig)


def parse_scenario(data: dict[str, Any], file: str | Path | None = None) -> ScenarioConfig:
    """Validate an already parsed scenario document."""
    return parse_config(data, file, ScenarioConfig)


def as_scenario(config: Config) -> ScenarioConfig:
    """A plant configuration as a scenario (the default world when it has no ``[hil]``)."""
    if isinstance(config, ScenarioConfig):
        return config
    fields = {f: getattr(config, f) for f in Config.__dataclass_fields__}
    return ScenarioConfig(**fields)


def axis_params(hil: HilConfig, soft: tuple[float, float], stow: float, margin: float = 5.0) -> AxisParams:
    """Physical axis of the emulated drive: the scenario's mechanics, the tracker's travel.

    Hard limits sit ``margin`` degrees outside the soft limits; the drive powers up stowed.
    """
    return AxisParams(
        **hil.drive.axis_kwargs(),
        soft_min=soft[0],
        soft_max=soft[1],
        hard_min=soft[0] - margin,
        hard_max=soft[1] + margin,
        stow_angle=stow,
        initial_angle=stow,
    )


__all__ = [
    "FAULT_KINDS",
    "HilCamera",
    "HilConfig",
    "HilDrive",
    "HilFaultEvent",
    "HilFaultRate",
    "HilFaults",
    "HilMountOffset",
    "HilPanelCamera",
    "HilReflection",
    "HilSkyCamera",
    "HilSunGap",
    "HilWireRates",
    "ScenarioConfig",
    "as_scenario",
    "axis_params",
    "fault_targets",
    "load_scenario",
    "parse_scenario",
]
