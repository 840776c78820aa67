"""The ``[hil]`` table of a scenario file: what the emulated world looks like."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import date

from controller.config import Config, TableReader
from controller.errors import ConfigError
from hil.drive import AxisParams


@dataclass(frozen=True)
class HilConfig:
    """World settings (degrees, seconds).

    ``start``: first simulated day; each day runs from local mean midnight
    (UTC - longitude/15 h).  ``substeps``: truth samples per control period used for the
    pointing-error and energy figures.
    """

    start: date = date(2024, 3, 20)
    sky: tuple[str, ...] = ("clear",)   # regime per day, repeated cyclically
    seed: int = 0
    linke_turbidity: float = 3.0
    substeps: int = 4
    drive: dict = field(default_factory=dict)
    camera_profile: str = "recommended"
    camera_noise: bool = True
    camera_tilt_deg: float = 0.3   # the installation the shipped bundles were calibrated on


def parse_hil(config: Config) -> HilConfig:
    root = TableReader(config.raw, config.file)
    t = root.table("hil", {})
    start = t.get("start", (str, date), "2024-03-20", expected="a date (YYYY-MM-DD)")
    if isinstance(start, str):
        try:
            start = date.fromisoformat(start)
        except ValueError:
            raise ConfigError(config.file, "hil.start", "a date YYYY-MM-DD", start) from None
    d = t.table("drive", {})
    d.unknown_keys({"max_speed_dps", "accel_dps2", "backlash_deg", "encoder_resolution_deg",
                    "deadband_deg"})
    drive = dict(
        max_speed=d.number("max_speed_dps", 1.0, lo=0.01, hi=10, unit="deg/s"),
        accel=d.number("accel_dps2", 2.0, lo=0.01, hi=100, unit="deg/s^2"),
        backlash=d.number("backlash_deg", 0.05, lo=0, hi=2, unit="deg"),
        encoder_resolution=d.number("encoder_resolution_deg", 0.01, lo=0, hi=1, unit="deg"),
        deadband=d.number("deadband_deg", 0.02, lo=0, hi=1, unit="deg"),
    )
    from hil.sky import SKY_KINDS

    sky = t.get("sky", (str, list), "clear", expected=f"a sky kind or a list of them ({', '.join(SKY_KINDS)})")
    sky = [sky] if isinstance(sky, str) else sky
    for i, kind in enumerate(sky):
        if kind not in SKY_KINDS:
            raise ConfigError(config.file, f"hil.sky[{i}]" if len(sky) > 1 else "hil.sky",
                              f"one of {', '.join(SKY_KINDS)}", kind)
    if not sky:
        raise ConfigError(config.file, "hil.sky", "at least one sky kind", sky)
    cam = t.table("camera", {})
    cam.unknown_keys({"profile", "noise", "tilt_deg"})
    return HilConfig(
        camera_profile=cam.choice("profile", ("seed", "recommended"), "recommended"),
        camera_noise=cam.get("noise", bool, True),
        camera_tilt_deg=cam.number("tilt_deg", 0.3, lo=0, hi=10, unit="deg"),
        start=start,
        sky=tuple(sky),
        seed=t.integer("seed", 0, lo=0),
        linke_turbidity=t.number("linke_turbidity", 3.0, lo=1, hi=8),
        substeps=t.integer("substeps", 4, lo=1, hi=60),
        drive=drive,
    )


def axis_params(hil: HilConfig, soft: tuple[float, float], stow: float, margin: float = 5.0
                ) -> AxisParams:
    """Physical axis of the emulated drive: the scenario's mechanics, the tracker's travel.

    Hard limits sit ``margin`` degrees outside the soft limits; the drive powers up stowed.
    """
    return AxisParams(**hil.drive, soft_min=soft[0], soft_max=soft[1],
                      hard_min=soft[0] - margin, hard_max=soft[1] + margin,
                      stow_angle=stow, initial_angle=stow)
