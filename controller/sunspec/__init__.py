"""SunSpec northbound interface: model 1 + model 601 (tracker controller) over Modbus TCP.

The controller builds a :class:`PlantSnapshot` on request, the :class:`SunSpecServer`
serves it to SCADA and hands accepted operator writes back as :class:`OverrideCommand`.
See ``docs/sunspec.md`` for the register map and the write policy.
"""

from .config import SunSpecConfig
from .encode import DGR_SF, Identity
from .models import SUNSPEC_BASE_ADDRESS, SunSpecMap
from .server import SunSpecServer, SunSpecServerError
from .snapshot import OverrideCommand, PlantSnapshot, TrackerSnapshot

__all__ = [
    "DGR_SF",
    "Identity",
    "OverrideCommand",
    "PlantSnapshot",
    "SUNSPEC_BASE_ADDRESS",
    "SunSpecConfig",
    "SunSpecMap",
    "SunSpecServer",
    "SunSpecServerError",
    "TrackerSnapshot",
]
