"""Read a Modbus pyranometer (map in :mod:`firmware_protocol.pyranometer`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from firmware_protocol import decode
from firmware_protocol.pyranometer import PYR

from ..drives.base import DriveCommError, LinkStats
from ..drives.links import LinkConfig
from ..drives.modbus.client import checked, endpoint, modbus_client, retry_policy

MAX_PLAUSIBLE_W_M2 = 1600.0  # above the solar constant plus cloud enhancement: a fault
_FIRST = PYR["PYR_IRRADIANCE"].offset
_LAST = PYR["PYR_STATUS"].offset


@dataclass(frozen=True)
class IrradianceSample:
    """One reading: POSIX time (s) and global horizontal irradiance (W/m2)."""

    time: float
    ghi_w_m2: float


class ModbusPyranometer:
    """A pyranometer on a pymodbus asyncio client (the shared client of an RS-485 line, or
    a TCP connection of its own).

    The link is opened on the first read and reopened after it drops, so a sensor that
    was away at start-up (or a gateway that restarted) comes back by itself.
    :meth:`read` raises :class:`DriveCommError` on a link error (after the link's retries),
    a fault status or an implausible value, so a bad sample is never used.

    Parameters
    ----------
    client : pymodbus async client
        See :func:`~controller.drives.modbus.client.modbus_client`.
    device_id : int
        Modbus slave id.
    label : str
        Used in error messages.
    retries : int
        Extra attempts of a failed read.
    """

    def __init__(self, client: Any, device_id: int, label: str = "", retries: int = 0):
        self.client = client
        self.device_id = device_id
        self.label = label or f"pyranometer id {device_id}"
        self.policy = retry_policy(retries)
        self.stats = LinkStats()
        self._closed = False

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> ModbusPyranometer:
        """The pyranometer ``device_id`` on a Modbus ``link`` (must run in the event loop
        that will read it: pymodbus clients belong to their loop)."""
        return cls(
            modbus_client(link),
            device_id,
            label=f"pyranometer {endpoint(link)} id {device_id}",
            retries=link.retries,
        )

    async def connect(self) -> None:
        """Open the link if it is not open (``read`` does this by itself)."""
        if not self.client.connected and not await self.client.connect():
            raise DriveCommError(f"{self.label}: cannot open the link")

    async def read(self, t: float) -> IrradianceSample:
        """The irradiance now, stamped ``t`` (POSIX s)."""
        await self.connect()
        rr = await self.policy.run(
            lambda: checked(
                self.client.read_input_registers, _FIRST, count=_LAST - _FIRST + 1, device_id=self.device_id
            ),
            what="irradiance read",
            label=self.label,
            stats=self.stats,
        )
        words = rr.registers
        status = int(decode(PYR["PYR_STATUS"], [words[_LAST - _FIRST]]))
        if status & 0b11:
            raise DriveCommError(f"{self.label}: sensor reports status {status:#06x}")
        ghi = float(decode(PYR["PYR_IRRADIANCE"], [words[0]]))
        if not -10.0 <= ghi <= MAX_PLAUSIBLE_W_M2:
            raise DriveCommError(f"{self.label}: implausible irradiance {ghi} W/m2")
        return IrradianceSample(t, max(ghi, 0.0))

    async def close(self) -> None:
        if not self._closed:  # once: a shared line's client counts its users
            self._closed = True
            self.client.close()
