"""Weather stow: wind (from an anemometer), snow and hail (from an operator, SCADA or a flag).

Priorities follow commercial practice: the drives' own watchdog first (it works without
the controller), then wind, then snow and hail, then everything else (manual setpoints,
night, DIFFUSE, tracking).  Wind stow enters on the 3-s gust or on the 10-min mean and
leaves only after both have stayed below their (lower) resume thresholds for a dwell time;
an anemometer that gives no valid reading for ``silent_timeout_s`` counts as a storm.

Angles in degrees: a dual-axis tracker's stow is the elevation of its panel normal (90:
flat, facing up; its azimuth stays where the tracker's ``stow`` puts it), a row's is its
rotation (0: flat).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from .schema import Where, setting

StowReason = Literal["wind", "snow", "hail"]


@dataclass(frozen=True, kw_only=True)
class WindConfig:
    """Wind stow from a Modbus anemometer (map in firmware_protocol/anemometer.py)."""

    link: str = setting(doc="Name of the Modbus `[[links]]` table the anemometer is on.")
    device_id: int = setting(doc="Modbus slave id of the anemometer.", ge=1, le=247)
    gust_stow_m_s: float = setting(20.0, doc="Stow when the 3-s gust reaches this.", unit="m/s", ge=5, le=60)
    mean_stow_m_s: float = setting(
        14.0, doc="Stow when the 10-min mean reaches this.", unit="m/s", ge=3, le=50
    )
    gust_resume_m_s: float = setting(
        15.0, doc="Resume only with the gust below this ...", unit="m/s", ge=1, le=60
    )
    mean_resume_m_s: float = setting(
        10.0, doc="... and the 10-min mean below this ...", unit="m/s", ge=1, le=50
    )
    resume_dwell_s: float = setting(600.0, doc="... for this long.", unit="s", ge=0, le=86400)
    poll_s: float = setting(5.0, doc="Time between two anemometer readings.", unit="s", ge=0.5, le=60)
    silent_timeout_s: float = setting(
        60.0, doc="No valid reading for this long: the anemometer is lost.", unit="s", ge=1, le=3600
    )
    on_silence: Literal["stow", "ignore"] = setting(
        "stow", doc="What a lost anemometer does: stow the plant (safe), or only alarm."
    )
    dual_axis_elevation_deg: float = setting(
        90.0,
        doc="Wind stow of dual-axis trackers: elevation of the panel normal (90: flat).",
        unit="deg",
        ge=-10,
        le=100,
    )
    single_axis_deg: float = setting(
        0.0, doc="Wind stow rotation of single-axis rows.", unit="deg", ge=-90, le=90
    )

    def __schema_check__(self, at: Where) -> WindConfig:
        if self.gust_resume_m_s >= self.gust_stow_m_s:
            raise at.child("gust_resume_m_s").error(
                f"less than gust_stow_m_s ({self.gust_stow_m_s:g} m/s)", self.gust_resume_m_s
            )
        if self.mean_resume_m_s >= self.mean_stow_m_s:
            raise at.child("mean_resume_m_s").error(
                f"less than mean_stow_m_s ({self.mean_stow_m_s:g} m/s)", self.mean_resume_m_s
            )
        if self.mean_stow_m_s >= self.gust_stow_m_s:  # a mean never passes the gusts it averages
            raise at.child("mean_stow_m_s").error(
                f"less than gust_stow_m_s ({self.gust_stow_m_s:g} m/s; at or above it, it never acts)",
                self.mean_stow_m_s,
            )
        if self.silent_timeout_s < self.poll_s:
            raise at.child("silent_timeout_s").error(
                f"at least poll_s ({self.poll_s:g} s)", self.silent_timeout_s
            )
        return self


@dataclass(frozen=True, kw_only=True)
class StowConfig:
    """Snow and hail stow: on an operator or SCADA command, or on a scheduled flag."""

    snow_dual_axis_elevation_deg: float = setting(
        30.0,
        doc="Snow stow of dual-axis trackers: normal elevation (30: a 60-deg tilt sheds snow).",
        unit="deg",
        ge=-10,
        le=100,
    )
    snow_single_axis_deg: float = setting(
        55.0, doc="Snow stow rotation of rows (clamped to each row's max_angle).", unit="deg", ge=-90, le=90
    )
    hail_dual_axis_elevation_deg: float = setting(
        10.0,
        doc="Hail stow of dual-axis trackers (near vertical: hail strikes at a glance).",
        unit="deg",
        ge=-10,
        le=100,
    )
    hail_single_axis_deg: float = setting(
        60.0, doc="Hail stow rotation of rows (clamped to each row's max_angle).", unit="deg", ge=-90, le=90
    )
    flag_file: Path | None = setting(
        None,
        doc='A file whose first word is "snow", "hail" or '
        '"none", written by a scheduler or weather service; '
        "read every cycle.",
        path="new",
    )


@dataclass(frozen=True)
class WindSample:
    """One anemometer reading (m/s)."""

    time: float
    speed_m_s: float
    gust_m_s: float
    mean_10min_m_s: float


@dataclass(frozen=True)
class WindState:
    """The monitor's verdict: ``stow`` and why; ``alarm`` also when only alarming."""

    stow: bool
    alarm: bool
    reason: str = ""


class WindMonitor:
    """Wind stow with hysteresis and dwell, and a lost-anemometer timeout.

    Times in POSIX s of the controller's clock; feed every poll's outcome to :meth:`update`
    (a sample, or None when the reading failed or was implausible).
    """

    def __init__(self, config: WindConfig, start: float):
        self.config = config
        self.last_valid = start
        self.storm = False
        self.calm_since: float | None = None
        self.reason = ""
        self.last: WindSample | None = None

    def update(self, t: float, sample: WindSample | None) -> WindState:
        c = self.config
        if sample is not None and not all(
            math.isfinite(v) and v >= 0 for v in (sample.speed_m_s, sample.gust_m_s, sample.mean_10min_m_s)
        ):
            sample = None  # an impossible reading is no reading: it counts toward the silence
        if sample is not None:
            self.last_valid = t
            self.last = sample
            if sample.gust_m_s >= c.gust_stow_m_s or sample.mean_10min_m_s >= c.mean_stow_m_s:
                self.storm, self.calm_since = True, None
                self.reason = (
                    f"wind: gust {sample.gust_m_s:.1f} m/s, 10-min mean {sample.mean_10min_m_s:.1f} m/s"
                )
            elif self.storm:
                calm = sample.gust_m_s < c.gust_resume_m_s and sample.mean_10min_m_s < c.mean_resume_m_s
                if not calm:
                    self.calm_since = None
                elif self.calm_since is None:
                    self.calm_since = t
                if calm and t - self.calm_since >= c.resume_dwell_s:  # type: ignore[operator]
                    self.storm, self.calm_since, self.reason = False, None, ""
        silent = t - self.last_valid >= c.silent_timeout_s
        if silent:
            if not self.storm or not self.reason.startswith("anemometer"):
                self.reason = f"anemometer silent for {t - self.last_valid:.0f} s"
            self.storm = self.storm or c.on_silence == "stow"
            self.calm_since = None
            return WindState(stow=self.storm, alarm=True, reason=self.reason)
        return WindState(stow=self.storm, alarm=self.storm, reason=self.reason)


def read_flag_file(path: Path) -> StowReason | None | str:
    """The stow request in a flag file: "snow", "hail", None (no request, or no file), or
    an error text for a file that says something else (the caller warns and ignores it)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return None
    except OSError as exc:
        return f"{path}: cannot read the stow flag ({exc.strerror})"
    words = text.split()
    word = words[0].lower() if words else "none"
    if word == "snow":
        return "snow"
    if word == "hail":
        return "hail"
    if word in ("none", "off", "clear"):
        return None
    return f"{path}: stow flag {words[0][:20]!r} is not snow, hail or none; ignored"
