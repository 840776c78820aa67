"""The controller's field devices, opened from the configuration: a drive link per tracker,
the pyranometer and the anemometer, each through its link (the drive-link registry and
:func:`~controller.drives.modbus.client.modbus_client`).

Call these inside the event loop that will use the devices (pymodbus clients belong to
the loop they are made in).
"""

from __future__ import annotations

from collections.abc import Mapping

from controller.config import Config
from controller.drives import DriveLink
from controller.drives.links import LinkConfig
from controller.drives.registry import open_drive
from controller.sensors.anemometer import ModbusAnemometer
from controller.sensors.pyranometer import ModbusPyranometer


def _links(config: Config, links: Mapping[str, LinkConfig] | None) -> Mapping[str, LinkConfig]:
    return config.links_by_name if links is None else {**config.links_by_name, **links}


def open_drives(config: Config, links: Mapping[str, LinkConfig] | None = None) -> dict[str, DriveLink]:
    """A drive link (not yet connected) per tracker, by tracker name.

    ``links`` replaces configured links by name (the simulator's endpoints).
    """
    by_name = _links(config, links)
    return {tr.name: open_drive(by_name[tr.link], tr.device_id) for tr in config.trackers}


def open_pyranometer(
    config: Config, links: Mapping[str, LinkConfig] | None = None
) -> ModbusPyranometer | None:
    """The configured pyranometer (None without a ``[pyranometer]`` table); it shares the
    client of an RS-485 line with the drives on it."""
    if config.pyranometer is None:
        return None
    link = _links(config, links)[config.pyranometer.link]
    return ModbusPyranometer.from_config(link, config.pyranometer.device_id)


def open_anemometer(config: Config, links: Mapping[str, LinkConfig] | None = None) -> ModbusAnemometer | None:
    """The anemometer of ``[wind]`` (None without one)."""
    if config.wind is None:
        return None
    link = _links(config, links)[config.wind.link]
    return ModbusAnemometer.from_config(link, config.wind.device_id)
