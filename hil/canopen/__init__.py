"""The drive emulator as CANopen CiA 402 slaves, and an slcan adapter on a pty.

- :mod:`hil.canopen.cia402`: the power state machine, bus-free.
- :mod:`hil.canopen.node`: one drive axis as a canopen ``LocalNode`` over the firmware.
- :mod:`hil.canopen.emulator`: drives on one CAN network, serviced by one thread.
- :mod:`hil.canopen.slcan`: a Lawicel/slcan USB-CAN adapter emulated on a pty.
"""

from .cia402 import Cia402StateMachine
from .emulator import CanopenDriveEmulator, CanopenNetworkEmulator, SafeNetwork
from .node import AxisNode, DriveBus, object_dictionary
from .slcan import SlcanAdapter, open_slcan_pty

__all__ = [
    "AxisNode",
    "CanopenDriveEmulator",
    "CanopenNetworkEmulator",
    "Cia402StateMachine",
    "DriveBus",
    "SafeNetwork",
    "SlcanAdapter",
    "object_dictionary",
    "open_slcan_pty",
]
