"""The drive-link registry, the python-can way: a link kind names ``"module:Class"``.

Classes are imported on first use, never by side effect.  Third-party backends register
through the entry-point group ``heliotrack.drive_links`` (name = link kind, value =
``"package.module:Class"``), as python-can's ``can.interface`` group does; a backend class
subclasses :class:`~controller.drives.base.DriveLink`, names its settings dataclass
(a :class:`~controller.drives.links.LinkConfig` subclass) in ``config_type`` and builds
itself in ``from_config(link, device_id)``.  A plug-in's ``[[links]]`` keys are validated
by the same schema as the built-in ones.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from functools import cache
from importlib.metadata import entry_points
from typing import TYPE_CHECKING

from ..errors import ConfigError, UserError

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


class BackendLoadError(UserError):
    """A registered backend cannot be imported, or is not a usable drive-link class."""


@cache
def _plugins() -> dict[str, str]:
    return {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}


def reload_plugins() -> None:
    """Read the installed entry points again (after installing a plug-in at run time)."""
    _plugins.cache_clear()
    backend_class.cache_clear()


def known_kinds() -> dict[str, str]:
    """Every link kind -> ``"module:Class"``: built-in and installed plug-ins (a plug-in
    cannot replace a built-in kind)."""
    return {**_plugins(), **BACKENDS}


@cache
def backend_class(kind: str) -> type[DriveLink]:
    """The backend class of ``kind``, imported now.

    Raises
    ------
    KeyError
        ``kind`` is not registered.
    BackendLoadError
        The registered ``"module:Class"`` cannot be loaded, or is not a
        :class:`~controller.drives.base.DriveLink` with a ``config_type``.
    """
    from .base import DriveLink
    from .links import LinkConfig

    target = known_kinds()[kind]
    origin = "built in" if kind in BACKENDS else f"entry point group {ENTRY_POINT_GROUP}"
    module, _, name = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module), name)
    except Exception as exc:  # a broken plug-in: any import-time error
        raise BackendLoadError(
            f"link kind {kind!r}: cannot load its backend {target!r} ({origin}): {type(exc).__name__}: {exc}"
        ) from exc
    config_type = getattr(cls, "config_type", None)
    if not (
        isinstance(cls, type)
        and issubclass(cls, DriveLink)
        and isinstance(config_type, type)
        and issubclass(config_type, LinkConfig)
    ):
        raise BackendLoadError(
            f"link kind {kind!r}: {target!r} ({origin}) is not a DriveLink "
            "subclass with a LinkConfig subclass as config_type"
        )
    return cls


class _ConfigTypes(Mapping[str, "type[LinkConfig]"]):
    """Link kind -> settings class; a class is imported only when its kind is looked up."""

    def __getitem__(self, kind: str) -> type[LinkConfig]:
        if kind not in known_kinds():
            raise KeyError(kind)
        return backend_class(kind).config_type

    def __iter__(self) -> Iterator[str]:
        return iter(known_kinds())

    def __len__(self) -> int:
        return len(known_kinds())


def link_config_types() -> Mapping[str, type[LinkConfig]]:
    """Link kind -> its settings class, importing a backend only when its kind is looked up
    (the schema's ``[[links]]`` variants; listing the kinds imports nothing)."""
    return _ConfigTypes()


def link_config_type(kind: str) -> type[LinkConfig] | None:
    """The settings class of ``kind``, or None when no backend of that kind is installed."""
    return link_config_types().get(kind)


def open_drive(link: LinkConfig, device_id: int) -> DriveLink:
    """A drive link (not yet connected) for the drive ``device_id`` on ``link``.

    Raises
    ------
    ConfigError
        No backend of ``link.kind`` is installed (the message lists the known kinds).
    BackendLoadError
        The backend cannot be loaded.
    """
    kinds = known_kinds()
    if link.kind not in kinds:
        raise ConfigError(None, f"links[{link.name!r}].kind", f"one of {', '.join(sorted(kinds))}", link.kind)
    return backend_class(link.kind).from_config(link, device_id)
