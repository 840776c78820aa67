"""The abstract drive link and the registry of its backends."""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

from firmware_protocol import Command, Fault, Mode, Status

if TYPE_CHECKING:
    from .links import LinkConfig


class DriveCommError(Exception):
    """The drive did not answer, or answered with an error, after the configured retries."""


@dataclass(frozen=True)
class AxisState:
    """What the drive reports for one axis (degrees, deg/s)."""

    actual_deg: float
    target_deg: float
    velocity_dps: float
    status: Status
    fault: Fault
    mode: Mode


@dataclass(frozen=True)
class DriveState:
    axis_count: int
    axes: tuple[AxisState, ...]
    device_status: Status = Status(0)

    @property
    def faulted(self) -> bool:
        return any(a.status & Status.FAULT for a in self.axes)


@dataclass
class LinkStats:
    transactions: int = 0
    errors: int = 0
    retries: int = 0
    latencies_s: list[float] = field(default_factory=list)


class DriveLink(abc.ABC):
    """One drive (one slave or node id, one or two axes) behind some transport.

    The interface is asyncio so that one controller process can keep many drives busy at
    once (a plant has hundreds of rows); backends of blocking libraries hand their slow
    calls to a thread.  Every call either succeeds or raises :class:`DriveCommError`; the
    backend applies the configured retries, the caller does not.
    """

    stats: LinkStats
    axis_count: int = 0
    label: str = ""
    #: The settings dataclass of this backend's ``[[links]]`` table.
    config_type: ClassVar[type[LinkConfig]]

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> DriveLink:
        """The drive ``device_id`` (slave or node id) on ``link``, not yet connected."""
        raise NotImplementedError(f"{cls.__name__} cannot be built from a configuration")

    @abc.abstractmethod
    async def connect(self) -> None:
        """Open the transport, check the drive's identification, set ``axis_count``."""

    @abc.abstractmethod
    async def close(self) -> None: ...

    @abc.abstractmethod
    async def read_state(self) -> DriveState: ...

    @abc.abstractmethod
    async def write_targets(self, angles_deg: Sequence[float]) -> None:
        """Set the target angle of axes 0.. (one value per axis, degrees)."""

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        """Write targets, then read the state; backends may merge the two on the wire."""
        await self.write_targets(angles_deg)
        return await self.read_state()

    @abc.abstractmethod
    async def heartbeat(self) -> None:
        """Refresh the firmware's watchdog."""

    @abc.abstractmethod
    async def command(self, cmd: Command) -> None: ...

    @abc.abstractmethod
    async def configure(self, *, heartbeat_timeout_s: float | None = None,
                        soft_limits: Sequence[tuple[float, float]] | None = None,
                        stow_angles: Sequence[float] | None = None) -> None:
        """Write configuration (only what is given)."""

    async def __aenter__(self):
        await self.connect()
        return self

    async def __aexit__(self, *exc):
        await self.close()


_BACKENDS: dict[str, Callable[..., DriveLink]] = {}


def register_backend(name: str, factory: Callable[..., DriveLink]) -> None:
    """Make a transport available to :func:`open_drive` under ``name``."""
    _BACKENDS[name] = factory


def backends() -> tuple[str, ...]:
    return tuple(sorted(_BACKENDS))


def open_drive(kind: str, **kwargs) -> DriveLink:
    """Create (not yet connect) a drive link of the registered ``kind``."""
    try:
        factory = _BACKENDS[kind]
    except KeyError:
        raise ValueError(f"unknown drive link {kind!r}; known: {', '.join(backends())}") from None
    return factory(**kwargs)
