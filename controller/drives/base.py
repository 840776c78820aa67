"""The abstract drive link and the registry of its backends."""

from __future__ import annotations

import abc
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from firmware_protocol import Command, Fault, Mode, Status


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
    """One drive (one slave id, one or two axes) behind some transport.

    Every call either succeeds or raises :class:`DriveCommError`; nothing is retried by
    the caller, the backend applies the configured retries.
    """

    stats: LinkStats

    @abc.abstractmethod
    def connect(self) -> None:
        """Open the transport and check the drive's identification (raises on mismatch)."""

    @abc.abstractmethod
    def close(self) -> None: ...

    @abc.abstractmethod
    def read_state(self) -> DriveState: ...

    @abc.abstractmethod
    def write_targets(self, angles_deg: Sequence[float]) -> None:
        """Set TARGET_ANGLE of axes 0.. (one value per axis)."""

    @abc.abstractmethod
    def heartbeat(self) -> None:
        """Refresh the firmware's watchdog."""

    @abc.abstractmethod
    def command(self, cmd: Command) -> None: ...

    @abc.abstractmethod
    def configure(self, *, heartbeat_timeout_s: float | None = None,
                  soft_limits: Sequence[tuple[float, float]] | None = None,
                  stow_angles: Sequence[float] | None = None) -> None:
        """Write configuration registers (only those given)."""

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc):
        self.close()


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
