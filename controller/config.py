"""The controller's TOML configuration: loaded, validated, turned into dataclasses.

Every error names the file, the key path and what was expected (:class:`ConfigError`).
Tables the controller does not own (``[hil]``) are left for their owners; their readers
use the same :class:`TableReader`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .diffuse import DiffuseConfig
from .errors import ConfigError
from .sun.source import Site

LINK_KINDS = ("modbus-rtu", "modbus-tcp", "canopen")
TRACKER_TYPES = ("dual-axis", "single-axis")
SUN_SOURCES = ("ephemeris", "hotspot")


class TableReader:
    """Typed access to one TOML table with errors that point at ``file: path.key``."""

    def __init__(self, data: dict, file: str | Path | None, path: str = ""):
        if not isinstance(data, dict):
            raise ConfigError(file, path, "a table", type(data).__name__)
        self.data = data
        self.file = file
        self.path = path

    def _key(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, kind: type | tuple, default: Any = ..., *, expected: str = ""):
        if key not in self.data:
            if default is ...:
                raise ConfigError(self.file, self._key(key), f"a value ({expected or _name(kind)}); the key is missing")
            return default
        value = self.data[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if float in kinds and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if isinstance(value, bool) and bool not in kinds:
            raise ConfigError(self.file, self._key(key), expected or _name(kind), value)
        if not isinstance(value, kinds):
            raise ConfigError(self.file, self._key(key), expected or _name(kind), value)
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(self.file, self._key(key), "a finite number", value)
        return value

    def number(self, key: str, default: Any = ..., *, lo: float = -math.inf, hi: float = math.inf,
               unit: str = "") -> float:
        v = self.get(key, float, default, expected=f"a number{' in ' + unit if unit else ''}")
        if v is None:
            return v
        if not lo <= v <= hi:
            raise ConfigError(self.file, self._key(key), f"a number in [{lo:g}, {hi:g}]{' ' + unit if unit else ''}", v)
        return v

    def integer(self, key: str, default: Any = ..., *, lo: int = -(2**63), hi: int = 2**63) -> int:
        v = self.get(key, int, default, expected="an integer")
        if not lo <= v <= hi:
            raise ConfigError(self.file, self._key(key), f"an integer in [{lo}, {hi}]", v)
        return v

    def choice(self, key: str, choices: tuple[str, ...], default: Any = ...) -> str:
        v = self.get(key, str, default, expected=f"one of {', '.join(choices)}")
        if v not in choices:
            raise ConfigError(self.file, self._key(key), f"one of {', '.join(choices)}", v)
        return v

    def pair(self, key: str, default: Any = ..., *, lo: float = -math.inf, hi: float = math.inf
             ) -> tuple[float, float]:
        v = self.get(key, list, default, expected="[min, max]")
        if (len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
                or not lo <= v[0] < v[1] <= hi):
            raise ConfigError(self.file, self._key(key), f"[min, max] with {lo:g} <= min < max <= {hi:g}", v)
        return float(v[0]), float(v[1])

    def table(self, key: str, default: Any = ...) -> "TableReader":
        v = self.get(key, dict, {} if default is not ... else ..., expected="a table")
        return TableReader(v, self.file, self._key(key))

    def tables(self, key: str) -> list["TableReader"]:
        v = self.get(key, list, [], expected="an array of tables ([[" + self._key(key) + "]])")
        out = []
        for i, item in enumerate(v):
            out.append(TableReader(item, self.file, f"{self._key(key)}[{i}]"))
        return out

    def unknown_keys(self, known: set[str]) -> None:
        extra = sorted(set(self.data) - known)
        if extra:
            raise ConfigError(self.file, self._key(extra[0]), f"one of the known keys ({', '.join(sorted(known))})", "unknown key")


def _name(kind) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {float: "a number", int: "an integer", str: "a string", bool: "true or false",
             list: "an array", dict: "a table"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


@dataclass(frozen=True)
class ControlConfig:
    """Control-loop settings.

    ``lead_s``: setpoints aim at the sun this far ahead of the cycle time, so that between
    two cycles the panel leads, then lags, the sun by the same amount (default: half a
    period).  ``heartbeat_timeout_s``: written to each drive at start; must exceed the
    period (default three periods, at least 5 s).
    """

    period_s: float = 60.0
    min_elevation_deg: float = 0.0
    lead_s: float = 30.0
    heartbeat_timeout_s: float = 180.0
    sun_source: str = "ephemeris"


@dataclass(frozen=True)
class LinkConfig:
    name: str
    kind: str
    port: str = ""          # serial device, or "hil" for a simulator-made pty
    baudrate: int = 115200
    host: str = "127.0.0.1"
    tcp_port: int = 502
    timeout_s: float = 0.5
    retries: int = 2


@dataclass(frozen=True)
class TrackerConfig:
    """One tracker (dual-axis) or row (single-axis) and the drive that moves it.

    Angles in degrees.  Dual-axis: axis 0 is the azimuth of the panel normal (clockwise
    from north, within ``azimuth_limits``, which may extend past 0/360), axis 1 its
    elevation.  Single-axis: axis 0 is pvlib's rotation angle ``tracker_theta``.
    """

    name: str
    type: str
    link: str
    device_id: int
    azimuth_limits: tuple[float, float] = (0.0, 360.0)
    elevation_limits: tuple[float, float] = (0.0, 90.0)
    stow: tuple[float, ...] = (180.0, 90.0)
    axis_azimuth: float = 180.0
    axis_tilt: float = 0.0
    max_angle: float = 55.0
    gcr: float = 0.4
    cross_axis_tilt: float = 0.0
    backtrack: bool = True

    @property
    def axes(self) -> int:
        return 2 if self.type == "dual-axis" else 1

    @property
    def row_geometry(self):
        from .geometry import RowGeometry
        return RowGeometry(self.axis_azimuth, self.axis_tilt, self.max_angle, self.gcr,
                           self.cross_axis_tilt, self.backtrack)

    @property
    def soft_limits(self) -> list[tuple[float, float]]:
        if self.type == "dual-axis":
            return [self.azimuth_limits, self.elevation_limits]
        return [(-self.max_angle, self.max_angle)]


@dataclass(frozen=True)
class HotspotConfig:
    """The convex-surface camera sensor (``[hotspot]``); paths resolved against the file.

    ``frames``: "hil" (the simulator renders them), a folder of timestamped images
    (replay), or "device:N" (OpenCV camera N).  ``interval_s``: seconds between frames
    the controller measures (0: one every control cycle); the sun-path filter predicts in
    between, as it does through cloud gaps.
    """

    calibration: str
    frames: str = "hil"
    algorithm: str = "default"
    interval_s: float = 0.0


@dataclass(frozen=True)
class SunPathSettings:
    """The sun-path filter behind camera sensors (``[sunpath]``).

    ``state``: file where the learned state persists (None: not persisted).
    ``site_known``: give the filter the configured site (and the ephemeris fallback);
    false makes it learn the site from the sky alone.
    """

    state: str | None = None
    site_known: bool = True


@dataclass(frozen=True)
class PyranometerConfig:
    """A Modbus pyranometer on one of the links (``[pyranometer]``)."""

    link: str
    device_id: int


@dataclass(frozen=True)
class Config:
    site: Site
    control: ControlConfig
    links: dict[str, LinkConfig]
    trackers: tuple[TrackerConfig, ...]
    pyranometer: PyranometerConfig | None = None
    diffuse: DiffuseConfig = field(default_factory=lambda: DiffuseConfig(enabled=False))
    hotspot: HotspotConfig | None = None
    sunpath: SunPathSettings = SunPathSettings()
    file: str = "<config>"
    raw: dict = field(default_factory=dict, repr=False, compare=False)


def load_config(path: str | Path) -> Config:
    """Read and validate a TOML configuration file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(path, "", f"a readable TOML file ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(path, "", "UTF-8 text") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(path, "", f"valid TOML ({exc})") from None
    return parse_config(data, path)


def parse_config(data: dict, file: str | Path | None = None) -> Config:
    root = TableReader(data, file)
    site = _site(root.table("site"))
    control = _control(root.table("control", {}))
    links = {}
    for t in root.tables("links"):
        link = _link(t)
        if link.name in links:
            raise ConfigError(file, f"{t.path}.name", "a unique link name", link.name)
        links[link.name] = link
    trackers = []
    for t in root.tables("trackers"):
        tr = _tracker(t, links)
        if any(o.name == tr.name for o in trackers):
            raise ConfigError(file, f"{t.path}.name", "a unique tracker name", tr.name)
        if any(o.link == tr.link and o.device_id == tr.device_id for o in trackers):
            raise ConfigError(file, f"{t.path}.device_id", f"an id not used on link {tr.link!r} already", tr.device_id)
        trackers.append(tr)
    if not trackers:
        raise ConfigError(file, "trackers", "at least one [[trackers]] table")
    pyr = None
    if root.has("pyranometer"):
        t = root.table("pyranometer")
        link = t.get("link", str)
        if link not in links:
            raise ConfigError(file, "pyranometer.link", "the name of a [[links]] table", link)
        pyr = PyranometerConfig(link, t.integer("device_id", lo=1, hi=247))
        if any(tr.link == link and tr.device_id == pyr.device_id for tr in trackers):
            raise ConfigError(file, "pyranometer.device_id", f"an id not used by a drive on {link!r}", pyr.device_id)
    diffuse = _diffuse(root.table("diffuse", {}), pyr is not None)
    if diffuse.enabled and control.period_s > 60:
        raise ConfigError(file, "diffuse.enabled", "false when control.period_s > 60 s (the sky "
                          "classifier needs a pyranometer sample at least every minute)", True)
    hotspot = _hotspot(root, file) if control.sun_source == "hotspot" or root.has("hotspot") else None
    if control.sun_source == "hotspot" and hotspot is None:
        raise ConfigError(file, "hotspot", "a [hotspot] table when control.sun_source = \"hotspot\"")
    sunpath = _sunpath(root.table("sunpath", {}), file)
    return Config(site, control, links, tuple(trackers), pyr, diffuse, hotspot, sunpath,
                  str(file), data)


def _relative(path: str, file) -> str:
    base = Path(file).parent if file not in (None, "<config>") and not str(file).startswith("<") else Path.cwd()
    return str((base / path).resolve()) if not Path(path).is_absolute() else path


def _hotspot(root: TableReader, file) -> HotspotConfig | None:
    if not root.has("hotspot"):
        return None
    t = root.table("hotspot")
    t.unknown_keys({"calibration", "frames", "algorithm", "interval_s"})
    frames = t.get("frames", str, "hil")
    if frames not in ("hil",) and not frames.startswith("device:"):
        frames = _relative(frames, file)
    return HotspotConfig(calibration=_relative(t.get("calibration", str), file), frames=frames,
                         algorithm=t.choice("algorithm", ("default", "seed"), "default"),
                         interval_s=t.number("interval_s", 0.0, lo=0.0, hi=86400.0, unit="s"))


def _sunpath(t: TableReader, file) -> SunPathSettings:
    t.unknown_keys({"state", "site_known"})
    state = t.get("state", str, None)
    return SunPathSettings(state=_relative(state, file) if state else None,
                           site_known=t.get("site_known", bool, True))


def _diffuse(t: TableReader, have_sensor: bool) -> DiffuseConfig:
    t.unknown_keys({"enabled", "window_h", "exit_window_h", "dwell_s", "method"})
    enabled = t.get("enabled", bool, have_sensor)
    if enabled and not have_sensor:
        raise ConfigError(t.file, "diffuse.enabled", "false unless a [pyranometer] is configured", True)
    return DiffuseConfig(
        enabled=enabled,
        window_h=t.number("window_h", 2.0, lo=0.25, hi=24, unit="h"),
        exit_window_h=t.number("exit_window_h", 0.25, lo=0.25, hi=24, unit="h"),
        dwell_s=t.number("dwell_s", 900.0, lo=0, hi=86400, unit="s"),
        method=t.choice("method", ("default", "seed"), "default"))


def _site(t: TableReader) -> Site:
    return Site(
        latitude=t.number("latitude", lo=-90, hi=90, unit="deg"),
        longitude=t.number("longitude", lo=-180, hi=180, unit="deg"),
        altitude=t.number("altitude", 0.0, lo=-500, hi=9000, unit="m"),
        pressure_pa=t.number("pressure_pa", None, lo=30000, hi=110000, unit="Pa"),
        temperature_c=t.number("temperature_c", 12.0, lo=-60, hi=60, unit="degC"),
        name=t.get("name", str, ""),
    )


def _control(t: TableReader) -> ControlConfig:
    t.unknown_keys({"period_s", "min_elevation_deg", "lead_s", "heartbeat_timeout_s", "sun_source"})
    period = t.number("period_s", 60.0, lo=0.05, hi=3600, unit="s")
    lead = t.number("lead_s", period / 2, lo=0, hi=3600, unit="s")
    hb = t.number("heartbeat_timeout_s", max(3 * period, 5.0), lo=0, hi=6553, unit="s")
    if 0 < hb <= period:
        raise ConfigError(t.file, f"{t._key('heartbeat_timeout_s')}", f"more than control.period_s ({period:g} s), or 0 to disable", hb)
    return ControlConfig(
        period_s=period,
        min_elevation_deg=t.number("min_elevation_deg", 0.0, lo=-5, hi=45, unit="deg"),
        lead_s=lead, heartbeat_timeout_s=hb,
        sun_source=t.choice("sun_source", SUN_SOURCES, "ephemeris"),
    )


def _link(t: TableReader) -> LinkConfig:
    kind = t.choice("kind", LINK_KINDS)
    return LinkConfig(
        name=t.get("name", str), kind=kind,
        port=t.get("port", str, "hil" if kind == "modbus-rtu" else ""),
        baudrate=t.integer("baudrate", 115200, lo=1200, hi=4_000_000),
        host=t.get("host", str, "127.0.0.1"),
        tcp_port=t.integer("tcp_port", 502, lo=0, hi=65535),
        timeout_s=t.number("timeout_s", 0.5, lo=0.001, hi=60, unit="s"),
        retries=t.integer("retries", 2, lo=0, hi=10),
    )


def _tracker(t: TableReader, links: dict[str, LinkConfig]) -> TrackerConfig:
    ttype = t.choice("type", TRACKER_TYPES)
    link = t.get("link", str)
    if link not in links:
        raise ConfigError(t.file, f"{t.path}.link", f"the name of a [[links]] table ({', '.join(links) or 'none defined'})", link)
    common = dict(name=t.get("name", str), type=ttype, link=link,
                  device_id=t.integer("device_id", lo=1, hi=247))
    if ttype == "dual-axis":
        az = t.pair("azimuth_limits", (0.0, 360.0), lo=-360, hi=720)
        el = t.pair("elevation_limits", (0.0, 90.0), lo=-10, hi=100)
        stow = t.get("stow", list, [180.0, 90.0], expected="[azimuth, elevation] in degrees")
        if len(stow) != 2 or not all(isinstance(x, (int, float)) for x in stow):
            raise ConfigError(t.file, f"{t.path}.stow", "[azimuth, elevation] in degrees", stow)
        return TrackerConfig(**common, azimuth_limits=az, elevation_limits=el,
                             stow=(float(stow[0]), float(stow[1])))
    max_angle = t.number("max_angle", 55.0, lo=1, hi=90, unit="deg")
    return TrackerConfig(
        **common,
        axis_azimuth=t.number("axis_azimuth", 180.0, lo=0, hi=360, unit="deg"),
        axis_tilt=t.number("axis_tilt", 0.0, lo=0, hi=45, unit="deg"),
        max_angle=max_angle,
        gcr=t.number("gcr", 0.4, lo=0.01, hi=1.0),
        cross_axis_tilt=t.number("cross_axis_tilt", 0.0, lo=-30, hi=30, unit="deg"),
        backtrack=t.get("backtrack", bool, True),
        stow=(t.number("stow", 0.0, lo=-max_angle, hi=max_angle, unit="deg"),),
    )
