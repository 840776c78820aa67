"""The CANopen CiA 402 drive link (``canopen``), on python-can through the canopen library.

- :mod:`.network`: the canopen ``Network`` of a bus, shared by its drives, and the
  master's heartbeat;
- :mod:`.axis`: the master's bookkeeping of one axis node (TPDO values and ages);
- :mod:`.drive`: :class:`CanopenDrive`, one heliotrack drive (one node per axis).
"""

from .axis import Axis402
from .drive import CanopenDrive, SetPointNotAcknowledged
from .network import SharedNetwork, send_master_heartbeat

__all__ = ["Axis402", "CanopenDrive", "SetPointNotAcknowledged", "SharedNetwork", "send_master_heartbeat"]
