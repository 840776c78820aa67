"""The drive-link registry, the python-can way: a link kind names ``"module:Class"``.

Classes are imported on first use, never by side effect.  Third-party backends register
through the entry-point group ``heliotrack.drive_links`` (name = link kind, value =
``"package.module:Class"``), as python-can's ``can.interface`` group does; a backend class
subclasses :class:`~controller.drives.base.DriveLink`, names its settings dataclass
(a :class:`~controller.drives.links.LinkConfig` subclass) in ``config_type`` and builds
itself in ``from_config(link, device_id)``.
"""

from __future__ import annotations

import importlib
from functools import cache
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .base import DriveLink
    from .links import LinkConfig

ENTRY_POINT_GROUP = "heliotrack.drive_links"

#: Built-in link kinds.
BACKENDS: dict[str, str] = {
    "modbus-rtu": "controller.drives.modbus:ModbusRtuDrive",
    "modbus-tcp": "controller.drives.modbus:ModbusTcpDrive",
    "canopen": "controller.drives.canopen:CanopenDrive",
}


@cache
def _plugins() -> dict[str, str]:
    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def known_kinds() -> dict[str, str]:
    """Every link kind: built-in and installed plug-ins (a plug-in cannot replace a
    built-in kind)."""
    return {**_plugins(), **BACKENDS}


@cache
def backend_class(kind: str) -> type[DriveLink]:
    """The backend class of ``kind``, imported now.

    Raises
    ------
    KeyError
        ``kind`` is not registered.
    ImportError, AttributeError
        The registered ``"module:Class"`` cannot be loaded.
    """
    target = known_kinds()[kind]
    module, _, name = target.partition(":")
    cls = getattr(importlib.import_module(module), name)
    return cls


def link_config_types() -> dict[str, type[LinkConfig]]:
    """Link kind -> its settings class (imports every backend; for the reference docs)."""
    return {kind: backend_class(kind).config_type for kind in known_kinds()}


def link_config_type(kind: str) -> type[LinkConfig] | None:
    """The settings class of ``kind``, or None when no backend of that kind is installed."""
    if kind not in known_kinds():
        return None
    return backend_class(kind).config_type


def open_drive(link: LinkConfig, device_id: int) -> DriveLink:
    """A drive link (not yet connected) for the drive ``device_id`` on ``link``."""
    return backend_class(link.kind).from_config(link, device_id)
