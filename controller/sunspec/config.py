"""The ``[sunspec]`` configuration table.

::

    [sunspec]
    enabled = true
    host = "127.0.0.1"          # bind address; "0.0.0.0" only on a plant network
    port = 1502                 # 0 = any free port (reported by the server)
    device_address = 1          # Modbus unit id, model 1 DA
    writes_enabled = false      # operator overrides from SCADA
    allow = ["127.0.0.1"]       # client addresses or networks allowed to write
    serial_number = ""          # model 1 SN

A table of :class:`controller.config.Config`, read by the one schema validator.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from ..schema import Where, setting


@dataclass(frozen=True, kw_only=True)
class SunSpecConfig:
    """The northbound SunSpec (model 601) Modbus TCP server, for plant SCADA."""

    enabled: bool = setting(False, doc="Serve SunSpec.")
    host: str = setting(
        "127.0.0.1", doc='Address to bind, an IP literal ("0.0.0.0" only on a plant network).'
    )
    port: int = setting(1502, doc="TCP port (0: any free port, reported at start).", ge=0, le=65535)
    writes_enabled: bool = setting(False, doc="Take operator overrides from SCADA.")
    allow: tuple[str, ...] = setting(("127.0.0.1",), doc="Client addresses or networks allowed to write.")
    device_address: int = setting(1, doc="Modbus unit id (model 1 DA).", ge=1, le=247)
    serial_number: str = setting("", doc="Model 1 serial number.")

    def __schema_check__(self, at: Where) -> SunSpecConfig:
        try:
            ipaddress.ip_address(self.host)
        except ValueError:
            # a literal address only: a host name could resolve to an unexpected interface
            raise at.child("host").error('an IP address literal such as "127.0.0.1"', self.host) from None
        for i, a in enumerate(self.allow):
            try:
                ipaddress.ip_network(a, strict=False)
            except ValueError:
                raise (
                    at.child("allow")
                    .item(i)
                    .error('an IP address or network such as "10.0.0.5" or "10.0.0.0/24"', a)
                ) from None
        return self
