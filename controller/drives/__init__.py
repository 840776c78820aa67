"""Drive links: how the controller talks to drive firmware (Modbus RTU/TCP, CANopen, plug-ins).

A transport is a :class:`~controller.drives.base.DriveLink` backend named by its link kind
in :mod:`controller.drives.registry`, in the spirit of python-can's interface registry:
``open_drive(link, device_id)`` imports the backend of ``link.kind`` on first use and
builds the drive with ``Backend.from_config``.  Importing this package imports no backend
(neither pymodbus nor canopen).
"""

from .base import AxisState, DriveCommError, DriveLink, DriveState, LinkSettingsError, LinkStats
from .registry import open_drive

__all__ = [
    "AxisState",
    "DriveCommError",
    "DriveLink",
    "DriveState",
    "LinkSettingsError",
    "LinkStats",
    "open_drive",
]
