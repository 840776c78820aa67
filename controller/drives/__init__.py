"""Drive links: how the controller talks to drive firmware (Modbus RTU/TCP; CANopen later).

A transport is a :class:`~controller.drives.base.DriveLink` backend registered by name, in
the spirit of python-can's interface registry; :func:`open_drive` picks one from config.
"""

from .base import AxisState, DriveCommError, DriveLink, DriveState, open_drive, register_backend

# Importing the backends registers them.
from . import canopen as _canopen  # noqa: F401,E402
from . import modbus as _modbus  # noqa: F401,E402

__all__ = ["AxisState", "DriveCommError", "DriveLink", "DriveState", "open_drive",
           "register_backend"]
