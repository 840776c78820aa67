"""The controller's configuration (a plant or scenario TOML file), as schema dataclasses.

:func:`load_config` reads a file against :class:`Config` with the one generic validator of
:mod:`controller.schema`: every error names the file, the key path and what was expected,
and unknown keys or tables are errors.  The application layer extends :class:`Config` with
the tables it owns (the simulator's ``[hil]``, see ``heliotrack.scenario``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal, TypeVar

from .closedloop.settings import TRACKER_FIELD, ClosedLoopConfig
from .diffuse import DiffuseConfig
from .drives.links import LinkConfig, ModbusRtuLink, ModbusTcpLink
from .drives.registry import link_config_types
from .errors import ConfigError
from .schema import DERIVED, Where, checked_path, internal, load, load_file, setting, variants
from .sun.source import Site
from .sunspec.config import SunSpecConfig
from .trackers import TRACKER_CLASSES, DualAxisTracker, SingleAxisTracker, TrackerConfig
from .weather import StowConfig, WindConfig

SunSourceKind = Literal["ephemeris", "hotspot", "fisheye", "fused"]
C = TypeVar("C", bound="Config")


@dataclass(frozen=True, kw_only=True)
class ControlConfig:
    """Control-loop settings."""

    period_s: float = setting(60.0, doc="Time between two control cycles.", unit="s", ge=0.05, le=3600)
    min_elevation_deg: float = setting(
        0.0,
        doc="Track while the sun is above this elevation (trackers wake 2 deg earlier).",
        unit="deg",
        ge=-5,
        le=45,
    )
    lead_s: float = setting(
        doc="Setpoints aim at the sun this far ahead of the cycle, so "
        "the panel leads then lags it by the same amount (at most period_s).",
        unit="s",
        ge=0,
        le=3600,
        derived="period_s / 2",
    )
    heartbeat_timeout_s: float = setting(
        doc="Drive watchdog: a drive that hears nothing "
        "for this long stows itself (must exceed "
        "period_s; the drives refuse to switch it off "
        "outside MAINTENANCE).",
        unit="s",
        gt=0,
        le=6553,
        derived="3 x period_s, at least 5 (set it when that is over 6553)",
    )
    sun_source: SunSourceKind = setting(
        "ephemeris",
        doc="Where the sun's direction comes "
        "from: the ephemeris at the configured site, the "
        "hotspot camera or the fisheye sky camera through the sun-path filter, or "
        '"fused": both cameras into the one filter (each observation with its own sigma).',
    )

    def __schema_check__(self, at: Where) -> ControlConfig:
        c = self
        if c.lead_s != c.lead_s:  # DERIVED (NaN)
            c = replace(c, lead_s=c.period_s / 2)
        if c.lead_s > c.period_s:  # aimed further ahead than the next setpoint replaces it
            raise at.child("lead_s").error(
                f"at most control.period_s ({c.period_s:g} s; default half of it)", c.lead_s
            )
        if c.heartbeat_timeout_s != c.heartbeat_timeout_s:
            c = replace(c, heartbeat_timeout_s=max(3 * c.period_s, 5.0))
            if c.heartbeat_timeout_s > 6553:  # the drives' register holds 6553.5 s
                raise at.child("heartbeat_timeout_s").error(
                    f"a value set (the default, 3 x period_s = {c.heartbeat_timeout_s:g} s, is over "
                    "the drives' 6553 s)"
                )
        if c.heartbeat_timeout_s <= c.period_s:
            raise at.child("heartbeat_timeout_s").error(
                f"more than control.period_s ({c.period_s:g} s)", c.heartbeat_timeout_s
            )
        return c


@dataclass(frozen=True, kw_only=True)
class HotspotConfig:
    """The convex-surface camera sensor."""

    calibration: Path = setting(doc="Calibration bundle (TOML, see docs/hotspot.md).", path="file")
    frames: str = setting(
        "hil",
        doc='Where frames come from: "hil" (rendered by the '
        'simulator), a folder of timestamped images (watched for new ones), "device:N" '
        '(OpenCV camera N), a stream URL ("rtsp://...", "http://...") or a video file '
        "(played in real time from start-up). Relative paths are from this file's folder.",
        nonempty=True,
    )
    algorithm: Literal["default", "seed"] = setting(
        "default", doc="Segmentation: the fast default or the paper's Algorithm 1."
    )
    interval_s: float = setting(
        0.0,
        doc="Time between frames the controller measures (0: "
        "one every control cycle); the sun-path filter predicts in "
        "between.",
        unit="s",
        ge=0,
        le=86400,
    )

    def __schema_check__(self, at: Where) -> HotspotConfig:
        if self.frames == "hil" or self.frames.startswith("device:") or "://" in self.frames:
            return self
        folder = Path(self.frames).expanduser()
        if not folder.is_absolute():
            folder = (at.folder / folder).resolve()
        return replace(self, frames=str(folder))


@dataclass(frozen=True, kw_only=True)
class FisheyeConfig(HotspotConfig):
    """The fisheye sky-camera sensor (docs/fisheye.md); its keys are those of `[hotspot]`."""

    calibration: Path = setting(doc="Fisheye calibration bundle (TOML, see docs/fisheye.md).", path="file")
    algorithm: Literal["default", "seed"] = setting(
        "default", doc="The default pipeline (rim on the sphere, gates), or the paper's (HSI, three rules)."
    )


@dataclass(frozen=True, kw_only=True)
class SunPathSettings:
    """The sun-path filter behind camera sensors."""

    state: Path | None = setting(
        None, doc="File where the learned state persists (none: not persisted).", path="new"
    )
    site_known: bool = setting(
        True,
        doc="Give the filter the configured site (and the "
        "ephemeris fallback); false: it learns the site from the sky.",
    )


@dataclass(frozen=True, kw_only=True)
class StoreConfig:
    """The SQLite store of learned state and history (survives power loss)."""

    path: Path | None = setting(
        None,
        doc="The store file (none: no store, and the sun-path "
        "state goes to `[sunpath] state`); `heliotrack run --state DIR` "
        "puts it in DIR.",
        path="new",
    )
    history_days: float = setting(
        30.0,
        doc="Observations and setpoints older than this are deleted (once a day).",
        unit="d",
        ge=1,
        le=3650,
    )


@dataclass(frozen=True, kw_only=True)
class PyranometerConfig:
    """A Modbus pyranometer on one of the links (SMP-like input registers)."""

    link: str = setting(doc="Name of a Modbus `[[links]]` table.")
    device_id: int = setting(doc="Modbus slave id.", ge=1, le=247)


@dataclass(frozen=True, kw_only=True)
class Config:
    """A plant: its site, its links and trackers, its sensors and control settings."""

    site: Site = setting(doc="Geographic site.")
    control: ControlConfig = setting(default_factory=ControlConfig, doc="Control loop.")
    links: tuple[LinkConfig, ...] = setting(
        (), doc="Links to the drives and sensors.", variants=variants("kind", link_config_types)
    )
    trackers: tuple[TrackerConfig, ...] = setting(
        doc="Trackers and rows.", variants=variants("type", TRACKER_CLASSES)
    )
    pyranometer: PyranometerConfig | None = setting(None, doc="Pyranometer (enables DIFFUSE).")
    diffuse: DiffuseConfig = setting(default_factory=DiffuseConfig, doc="DIFFUSE mode.")
    hotspot: HotspotConfig | None = setting(None, doc="Hotspot camera sensor.")
    fisheye: FisheyeConfig | None = setting(None, doc="Fisheye sky-camera sensor.")
    sunpath: SunPathSettings = setting(default_factory=SunPathSettings, doc="Sun-path filter.")
    sunspec: SunSpecConfig = setting(default_factory=SunSpecConfig, doc="SunSpec server.")
    wind: WindConfig | None = setting(None, doc="Wind stow from an anemometer.")
    stow: StowConfig = setting(default_factory=StowConfig, doc="Snow and hail stow.")
    store: StoreConfig = setting(default_factory=StoreConfig, doc="State and history store.")
    closedloop: ClosedLoopConfig | None = setting(
        None, doc="Panel-mounted closed loop (a camera on each panel; docs/fisheye.md)."
    )
    file: str = internal("<config>")

    @property
    def links_by_name(self) -> dict[str, LinkConfig]:
        return {link.name: link for link in self.links}

    def __schema_check__(self, at: Where) -> Config:
        links: dict[str, LinkConfig] = {}
        serial: dict[tuple[str, ...], ModbusRtuLink] = {}
        for i, link in enumerate(self.links):
            if link.name in links:
                raise (
                    at.child("links").item(i, link.name).child("name").error("a unique link name", link.name)
                )
            links[link.name] = link
            # a serial port is opened by one link only, whatever name (a symlink) it goes by
            if isinstance(link, ModbusRtuLink) and link.bus[0] == "serial":
                if link.bus in serial:
                    other = serial[link.bus]
                    same = "" if other.port == link.port else f" as {other.port}; both are {link.bus[1]}"
                    raise (
                        at.child("links")
                        .item(i, link.name)
                        .child("port")
                        .error(
                            f"a port no other link opens (link {other.name!r} has it{same}: put "
                            "every device of one RS-485 line on one link)",
                            link.port,
                        )
                    )
                serial[link.bus] = link
        if not self.trackers:
            raise at.child("trackers").error("at least one [[trackers]] table")
        names: set[str] = set()
        # device ids are unique per physical bus (two links may reach one gateway or CAN bus)
        used: dict[tuple[tuple[str, ...], int], str] = {}
        for i, tr in enumerate(self.trackers):
            here = at.child("trackers").item(i, tr.name)
            if tr.name in names:
                raise here.child("name").error("a unique tracker name", tr.name)
            names.add(tr.name)
            if tr.link not in links:
                raise here.child("link").error(
                    f"the name of a [[links]] table ({', '.join(links) or 'none defined'})", tr.link
                )
            bus = links[tr.link].bus
            for address in _addresses(links[tr.link], tr.device_id, tr.axes):
                if (bus, address) in used:
                    raise here.child("device_id").error(
                        f"an id not used on the bus of link {tr.link!r} already (by {used[bus, address]})",
                        tr.device_id,
                    )
                used[bus, address] = tr.name
            if links[tr.link].kind == "canopen" and tr.device_id + tr.axes - 1 > 126:
                raise here.child("device_id").error(
                    f"a CANopen node id with all {tr.axes} axes within 1..126 (127 is the master's)",
                    tr.device_id,
                )
            if links[tr.link].kind == "canopen" and self.control.heartbeat_timeout_s > 65.535:
                raise (
                    at.child("control")
                    .child("heartbeat_timeout_s")
                    .error(
                        f"at most 65.535 s with drives on CANopen link {tr.link!r} (the consumer "
                        "heartbeat time 0x1016 counts 16-bit milliseconds; the default is 3 x "
                        "period_s)",
                        self.control.heartbeat_timeout_s,
                    )
                )
        c = self
        pyr = self.pyranometer
        if pyr is not None:
            here = at.child("pyranometer")
            if pyr.link not in links:
                raise here.child("link").error("the name of a [[links]] table", pyr.link)
            if not isinstance(links[pyr.link], (ModbusRtuLink, ModbusTcpLink)):
                raise here.child("link").error("a Modbus link (modbus-rtu or modbus-tcp)", pyr.link)
            if (links[pyr.link].bus, pyr.device_id) in used:
                raise here.child("device_id").error(
                    f"an id not used by a drive on {pyr.link!r}", pyr.device_id
                )
        diffuse = self.diffuse
        if diffuse.enabled is None:
            c = replace(c, diffuse=replace(diffuse, enabled=pyr is not None))
        elif diffuse.enabled and pyr is None:
            raise (
                at.child("diffuse").child("enabled").error("false unless a [pyranometer] is configured", True)
            )
        if c.diffuse.enabled and self.control.period_s > 60:
            raise (
                at.child("diffuse")
                .child("enabled")
                .error(
                    "false when control.period_s > 60 s (the sky classifier needs a pyranometer "
                    "sample at least every minute)",
                    True,
                )
            )
        if self.wind is not None:
            self._check_wind(at.child("wind"), links, used)
        source = self.control.sun_source
        for table in ("hotspot", "fisheye"):
            if source in (table, "fused") and getattr(self, table) is None:
                raise at.child(table).error(f"a [{table}] table when control.sun_source = {source!r}")
        self._check_state_paths(at)
        sunspec = self.sunspec
        for i, link in enumerate(self.links):  # the server would bind the endpoint the link dials
            if (
                sunspec.enabled
                and isinstance(link, ModbusTcpLink)
                and link.host == sunspec.host
                and link.tcp_port == sunspec.port != 0
            ):
                raise (
                    at.child("sunspec")
                    .child("port")
                    .error(
                        f"a port other than links[{i}]'s ({link.name} reaches {link.host}:{link.tcp_port})",
                        sunspec.port,
                    )
                )
        for key in ("snow_dual_axis_elevation_deg", "hail_dual_axis_elevation_deg"):
            for tr in self.trackers:  # clamped silently before: the stow was not the one asked for
                lo, hi = tr.elevation_limits if isinstance(tr, DualAxisTracker) else (-math.inf, math.inf)
                if not lo <= getattr(self.stow, key) <= hi:
                    raise (
                        at.child("stow")
                        .child(key)
                        .error(
                            f"an elevation within every tracker's limits ({tr.name}: [{lo:g}, {hi:g}])",
                            getattr(self.stow, key),
                        )
                    )
        for i, name in enumerate(self.closedloop.trackers if self.closedloop is not None else ()):
            if name not in names:
                raise at.child("closedloop").child("trackers").item(i).error("a tracker name", name)
        cl = self.closedloop
        looped = (cl.trackers or names) if cl is not None and cl.enabled else ()
        if cl is not None and cl.frames != "hil" and len(looped) > 1 and TRACKER_FIELD not in cl.frames:
            raise (
                at.child("closedloop")
                .child("frames")
                .error(
                    f'one camera per panel: "{TRACKER_FIELD}" in it ({len(looped)} trackers in the loop)',
                    cl.frames,
                )
            )
        return c

    def _check_state_paths(self, at: Where) -> None:
        """The files the controller writes are none of the files it reads: an unreadable
        state file is moved aside, and so would a plant file or a bundle be."""
        read: dict[Path, str] = {}
        if at.file is not None and not at.file.startswith("<"):  # `file` is set after the checks
            read[Path(at.file).resolve()] = "the configuration file itself"
        for table in ("hotspot", "fisheye"):
            sensor = getattr(self, table)
            if sensor is not None:
                read[Path(sensor.calibration).resolve()] = f"{table}.calibration"
        cl = self.closedloop
        if cl is not None and cl.enabled:  # each looped camera's lens bundle ("{tracker}" in it)
            where = at.child("closedloop").child("calibration")
            for tr in self.trackers:
                if not cl.trackers or tr.name in cl.trackers:
                    read[checked_path(str(cl.lens(tr.name)), where, "file").resolve()] = (
                        "closedloop.calibration"
                    )
        written = (
            (at.child("store").child("path"), self.store.path),
            (at.child("sunpath").child("state"), self.sunpath.state),
            (at.child("closedloop").child("state"), cl.state if cl is not None else None),
        )
        for where, path in written:
            if path is not None and Path(path).resolve() in read:
                raise where.error(f"a file of its own (this is {read[Path(path).resolve()]})", str(path))
        if self.store.path is not None and self.store.path == self.sunpath.state:
            raise (
                at.child("sunpath")
                .child("state")
                .error(
                    "a file other than store.path (the store is SQLite, the state JSON)",
                    str(self.sunpath.state),
                )
            )

    def _check_wind(
        self, at: Where, links: dict[str, LinkConfig], used: dict[tuple[tuple[str, ...], int], str]
    ) -> None:
        wind = self.wind
        assert wind is not None
        if wind.link not in links:
            raise at.child("link").error("the name of a [[links]] table", wind.link)
        if not isinstance(links[wind.link], (ModbusRtuLink, ModbusTcpLink)):
            raise at.child("link").error("a Modbus link (modbus-rtu or modbus-tcp)", wind.link)
        pyr = self.pyranometer
        bus = links[wind.link].bus
        if (bus, wind.device_id) in used or (
            pyr is not None and (links[pyr.link].bus, pyr.device_id) == (bus, wind.device_id)
        ):
            raise at.child("device_id").error(f"an id not used on {wind.link!r} already", wind.device_id)
        # the wind stow angle becomes each drive's STOW_ANGLE: it must be reachable
        for tr in self.trackers:
            if isinstance(tr, SingleAxisTracker) and abs(wind.single_axis_deg) > tr.max_angle:
                raise at.child("single_axis_deg").error(
                    f"a rotation within every row's max_angle ({tr.name}: {tr.max_angle:g} deg)",
                    wind.single_axis_deg,
                )
            if isinstance(tr, DualAxisTracker):
                lo, hi = tr.elevation_limits
                if not lo <= wind.dual_axis_elevation_deg <= hi:
                    raise at.child("dual_axis_elevation_deg").error(
                        f"an elevation within every tracker's limits ({tr.name}: [{lo:g}, {hi:g}])",
                        wind.dual_axis_elevation_deg,
                    )


def _addresses(link: LinkConfig, device_id: int, axes: int) -> range:
    """Bus addresses a drive occupies: one slave id on Modbus, one node per axis on CAN."""
    return range(device_id, device_id + (axes if link.kind == "canopen" else 1))


def load_config(path: str | Path, schema: type[C] = Config) -> C:  # type: ignore[assignment]
    """Read and validate a configuration file (:class:`Config` or an extension of it)."""
    return load_file(schema, path)


def parse_config(data: dict[str, Any], file: str | Path | None = None, schema: type[C] = Config) -> C:  # type: ignore[assignment]
    """Validate an already parsed document."""
    return load(schema, data, file if file is not None else "<config>")


__all__ = [
    "Config",
    "ConfigError",
    "ControlConfig",
    "DualAxisTracker",
    "FisheyeConfig",
    "HotspotConfig",
    "PyranometerConfig",
    "SingleAxisTracker",
    "SunPathSettings",
    "TrackerConfig",
    "load_config",
    "parse_config",
    "DERIVED",
]
