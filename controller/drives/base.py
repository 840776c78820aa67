"""The abstract drive link: what every backend (Modbus RTU/TCP, CANopen, plug-ins) offers.

Backends are found through :mod:`controller.drives.registry`; nothing registers by being
imported.
"""

from __future__ import annotations

import abc
import dataclasses
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

from firmware_protocol import Command, Fault, Mode, Status

from ..errors import UserError

if TYPE_CHECKING:
    from .configuration import DriveConfiguration
    from .links import LinkConfig


class DriveCommError(Exception):
    """The drive did not answer, or answered with an error, after the configured retries."""


class DriveNoAnswer(DriveCommError):
    """Every attempt of a transaction failed without the drive refusing it (no answer, or
    a garbled one): ``label`` says where, ``attempts`` how many were made."""

    def __init__(self, label: str, what: str, attempts: int, last: BaseException | None):
        self.label, self.what, self.attempts, self.last = label, what, attempts, last
        super().__init__(f"{label}: {what} failed after {attempts} attempt(s): {last}")


class DriveRefused(DriveCommError):
    """The drive answered the transaction with a refusal another attempt would repeat (a
    Modbus exception response, an SDO abort); ``refusal`` is the backend's exception."""

    def __init__(self, message: str, refusal: BaseException):
        super().__init__(message)
        self.refusal = refusal


class DriveHeld(DriveCommError):
    """The drive answers, but another party holds it where it is (a CANopen NMT stop, a CiA
    402 quick stop or disable by a service tool): reported, never overridden, and not a
    link failure (reconnecting would start it again)."""


class LinkSettingsError(UserError):
    """Two links disagree about one physical port (or a link cannot be used as given)."""


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
    """The state of every axis of one drive, and the union of their status bits."""

    axis_count: int
    axes: tuple[AxisState, ...]
    device_status: Status = Status(0)  # noqa: RUF009 - an immutable flag value

    @property
    def faulted(self) -> bool:
        return any(a.status & Status.FAULT for a in self.axes)


@dataclass(frozen=True)
class DriveIdentity:
    """What a drive says of itself (global registers / their CANopen mirrors)."""

    axis_count: int
    protocol_version: int  # major * 256 + minor
    firmware_version: int  # major * 256 + minor
    uptime_s: float

    @staticmethod
    def version_text(v: int) -> str:
        return f"{v >> 8}.{v & 0xFF}"


#: Latencies kept per link (the most recent).
LATENCY_WINDOW = 10_000


@dataclass
class LinkStats:
    """Counts of one drive link: attempts made, attempts failed, retries, and the latency
    of the last :data:`LATENCY_WINDOW` successful attempts (s; bounded: a controller runs
    for months)."""

    transactions: int = 0
    errors: int = 0
    retries: int = 0
    latencies_s: deque[float] = field(default_factory=lambda: deque(maxlen=LATENCY_WINDOW))


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
    #: What the drive held when its configuration was last read back (None: not yet, or a
    #: backend that cannot read it).
    configuration: DriveConfiguration | None = None
    #: Times the backend started the drive again by itself after it announced a reboot or a
    #: reset (CANopen boot-up): its configuration is gone, the loop configures it again.
    restarts: int = 0
    #: The settings dataclass of this backend's ``[[links]]`` table.
    config_type: ClassVar[type[LinkConfig]]
    #: The attribute holding the ``RetryPolicy`` that :meth:`connect` runs under (None: none).
    probe_policy: ClassVar[str | None] = None

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> DriveLink:
        """The drive ``device_id`` (slave or node id) on ``link``, not yet connected."""
        raise NotImplementedError(f"{cls.__name__} cannot be built from a configuration")

    @abc.abstractmethod
    async def connect(self) -> None:
        """Open the transport, check the drive's identification, set ``axis_count``."""

    @abc.abstractmethod
    async def close(self) -> None: ...

    async def probe(self) -> bool:
        """Connect if the drive answers the first time, without retries; True when connected.

        The loop probes a link that waits out its reconnection backoff once a cycle, so that
        a drive whose fault has cleared is back in the next cycle however long the backoff,
        while a drive still gone costs its bus one timeout a cycle.  It runs
        :meth:`connect` with the backend's ``RetryPolicy`` named by ``probe_policy`` cut to
        one attempt; a backend without one cannot try cheaply and waits for the backoff.
        """
        if self.probe_policy is None:
            return False
        saved = getattr(self, self.probe_policy)
        setattr(self, self.probe_policy, dataclasses.replace(saved, retries=0))
        try:
            await self.connect()
        except DriveCommError:
            return False
        finally:
            setattr(self, self.probe_policy, saved)
        return True

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

    async def identify(self) -> DriveIdentity | None:
        """Who the drive is and how long it has been up (a reboot resets ``uptime_s``);
        None from a backend that cannot tell (no reboot detection, ``check`` says so)."""
        return None

    async def heartbeat_identify(self) -> DriveIdentity | None:
        """A heartbeat, then :meth:`identify`: the loop's heartbeat round.  A backend may put
        both in one transaction (Modbus: one FC 23)."""
        await self.heartbeat()
        return await self.identify()

    async def read_configuration(self) -> DriveConfiguration | None:
        """The watchdog, soft limits and stow angles the drive holds now (None from a
        backend that cannot read them)."""
        return None

    @abc.abstractmethod
    async def configure(
        self,
        *,
        heartbeat_timeout_s: float | None = None,
        soft_limits: Sequence[tuple[float, float]] | None = None,
        stow_angles: Sequence[float] | None = None,
    ) -> None:
        """Write configuration (only what is given)."""

    async def __aenter__(self):
        await self.connect()
        return self

    async def __aexit__(self, *exc):
        await self.close()


def soft_limit_steps(
    current: tuple[float, float], limits: tuple[float, float] | None, stow: float | None
) -> list[tuple[float, float] | float]:
    """The writes that take one axis to new soft limits and stow angle (degrees) through
    states a firmware accepts: limits in order, the stow angle within them.

    A step is a ``(min, max)`` pair (written min first where a backend needs two writes)
    or a stow angle.  With both given, the limits first widen to the union of the current
    and the new ones, then the stow angle moves, then the limits narrow, so every state
    on the way holds the stow angle of its moment whatever the order of old and new.

    Parameters
    ----------
    current : (float, float)
        The axis's soft limits now (read from the drive; ignored unless both of the
        others are given).
    limits : (float, float), optional
        New soft limits.
    stow : float, optional
        New stow angle, within ``limits``.
    """
    if limits is None:
        return [] if stow is None else [stow]
    if stow is None:
        return [limits]
    union = (min(limits[0], current[0]), max(limits[1], current[1]))
    steps: list[tuple[float, float] | float] = [] if union == tuple(current) else [union]
    steps.append(stow)
    if limits != union:
        steps.append(limits)
    return steps
