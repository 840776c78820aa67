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

    def script(self, t0: float):
        """The :class:`hil.wind.WindScript` of this table, days counted from ``t0``."""
        from hil.wind import Storm, WindScript

        storms = tuple(
            Storm(parse_timestamp(s.start, "storm start", require_zone=True), s.peak_m_s, s.ramp_s, s.hold_s)
            for s in self.storms
        )
        return WindScript(t0, self.kinds, storms, seed=self.seed)


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
    wind: HilWind = setting(default_factory=HilWind, doc="Wind.")

    @property
    def skies(self) -> tuple[str, ...]:
        """The sky regime of each day of the cycle."""
        return (self.sky,) if isinstance(self.sky, str) else self.sky

    def __schema_check__(self, at: Where) -> HilConfig:
        if not isinstance(self.sky, str) and not self.sky:
            raise at.child("sky").error("at least one sky kind", list(self.sky))
        return self


@dataclass(frozen=True, kw_only=True)
class ScenarioConfig(Config):
    """A plant configuration run by the simulator: the plant, and the world around it."""

    hil: HilConfig = setting(default_factory=HilConfig, doc="The emulated world.")


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
    "HilCamera",
    "HilConfig",
    "HilDrive",
    "ScenarioConfig",
    "as_scenario",
    "axis_params",
    "load_scenario",
    "parse_scenario",
]
