"""Modbus drive links (``modbus-rtu``, ``modbus-tcp``) on pymodbus's asyncio clients.

- :mod:`.client`: the client of a link (one per serial port, shared by every device on
  the line), and what an answer means for the retry policy;
- :mod:`.drive`: the heliotrack drive over such a client.
"""

from .client import LineSettings, SharedSerialClient, modbus_client, retry_policy
from .drive import ModbusDrive, ModbusRtuDrive, ModbusTcpDrive

__all__ = [
    "LineSettings",
    "ModbusDrive",
    "ModbusRtuDrive",
    "ModbusTcpDrive",
    "SharedSerialClient",
    "modbus_client",
    "retry_policy",
]
