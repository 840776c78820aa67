"""Settings of the day-type classifier (``[sky]`` of a sky-settings file), on the schema."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from controller.schema import Where, load, setting

from .fractal import PAPER_SCALES_S, Criterion, Increments

Method = Literal["default", "seed"]
ThresholdRule = Literal["range", "tertiles", "fixed"]


@dataclass(frozen=True, kw_only=True)
class SkyConfig:
    """Settings of the day-type classifier (all have the paper's or a documented default)."""

    method: Method = setting(
        "default",
        doc="Which rule fills the class column: the paper's "
        "(fractal D + K_T) or the default (pyranometric sunshine).",
    )
    scales_s: tuple[float, ...] = setting(
        PAPER_SCALES_S,
        doc="Fractal scales (paper: 1, 2, 5, 7, 10, 14, 35 min); at least three.",
        unit="s",
        gt=0,
    )
    criterion: Criterion = setting(
        "slope-se", doc="Fit-range rule of the fractal dimension (see controller.sky.fractal)."
    )
    increments: Increments = setting("all-offsets", doc="Pair set of the variation S(dt).")
    min_elevation_deg: float = setting(
        0.0,
        doc="The fractal window is the part of the day with the sun above this elevation.",
        unit="deg",
        ge=-5,
        le=60,
    )
    max_missing_s: float = setting(
        3600.0,
        doc="Days with more daylight than this missing are excluded (paper: one hour).",
        unit="s",
        ge=0,
    )
    kt_threshold: float = setting(0.5, doc="K_T,I of the paper's rule.", ge=0, le=1.5)
    threshold_rule: ThresholdRule = setting(
        "range", doc="How D_I, D_II are set per year for the paper's rule."
    )
    d_thresholds: tuple[float, float] = setting(
        (1.19, 1.37),
        doc="(D_I, D_II) when fixed, and for years with too few days (paper's Table 1 means).",
        ge=1,
        le=2,
    )
    sunshine_bands: tuple[float, float] = setting(
        (0.8, 0.2),
        doc="(clear, overcast) fractions of daylight for the sunshine rules and truth.",
        ge=0,
        le=1,
    )
    kt_bands: tuple[float, float] = setting(
        (0.65, 0.35), doc="(clear, overcast) K_T bands of the K_T-only baseline.", ge=0, le=1.5
    )

    @classmethod
    def from_mapping(cls, data: dict, file=None, prefix: str = "sky") -> SkyConfig:
        """Build from a TOML table (e.g. ``[sky]``), naming the file and key on any error.

        Raises
        ------
        controller.errors.ConfigError
        """
        return load(cls, data, file if file is not None else "<sky settings>", prefix)

    def __schema_check__(self, at: Where) -> SkyConfig:
        if not self.d_thresholds[0] <= self.d_thresholds[1]:
            raise at.child("d_thresholds").error("(D_I, D_II) with D_I <= D_II", list(self.d_thresholds))
        if len(self.scales_s) < 3:
            raise at.child("scales_s").error("at least three positive scales (s)", list(self.scales_s))
        return self


@dataclass(frozen=True, kw_only=True)
class SkySettings:
    """A sky-settings file (``heliotrack classify --settings FILE``): one ``[sky]`` table."""

    sky: SkyConfig = setting(default_factory=SkyConfig, doc="Day-type classifier settings.")
