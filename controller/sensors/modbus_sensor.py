"""A read-only Modbus instrument on a link (pyranometer, anemometer): one block of input
registers read with the link's retries, on the link's shared client."""

from __future__ import annotations

import time
from typing import Any, ClassVar, Self

from ..drives.base import DriveCommError, LinkStats
from ..drives.links import LinkConfig
from ..drives.modbus.client import checked, endpoint, modbus_client, retry_policy, why_tcp_not_open


class ModbusSensor:
    """Base of the Modbus sensors.

    The link is opened on the first read and reopened after it drops, so a sensor that was
    away at start-up (or a gateway that restarted) comes back by itself.

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

    #: What the instrument is, for labels ("pyranometer").
    kind: ClassVar[str] = "sensor"

    def __init__(self, client: Any, device_id: int, label: str = "", retries: int = 0):
        self.client = client
        self.device_id = device_id
        self.label = label or f"{self.kind} id {device_id}"
        self.policy = retry_policy(retries)
        self.stats = LinkStats()
        self._closed = False

    @classmethod
    def from_config(cls, link: LinkConfig, device_id: int) -> Self:
        """The instrument ``device_id`` on a Modbus ``link`` (make it in the event loop that
        will read it: pymodbus clients belong to their loop)."""
        return cls(
            modbus_client(link),
            device_id,
            label=f"{cls.kind} {endpoint(link)} id {device_id}",
            retries=link.retries,
        )

    async def connect(self) -> None:
        """Open the link if it is not open (reads do this by themselves)."""
        if self.client.connected:
            return
        t0 = time.monotonic()
        if not await self.client.connect():
            why = await why_tcp_not_open(self.client, time.monotonic() - t0)
            raise DriveCommError(f"{self.label}: cannot open the link{why}")

    async def read_block(self, first: int, count: int, what: str) -> list[int]:
        """Input registers ``first .. first+count-1`` (DriveCommError after the retries)."""
        await self.connect()
        rr = await self.policy.run(
            lambda: checked(self.client.read_input_registers, first, count=count, device_id=self.device_id),
            what=what,
            label=self.label,
            stats=self.stats,
        )
        return list(rr.registers)

    async def close(self) -> None:
        if not self._closed:  # once: a shared line's client counts its users
            self._closed = True
            self.client.close()
