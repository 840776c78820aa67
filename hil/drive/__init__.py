"""Emulated slewing-drive firmware: physics (:mod:`.axis`) and registers (:mod:`.firmware`)."""

from .axis import AxisModel, AxisParams
from .firmware import DriveFirmware, FirmwareReject

__all__ = ["AxisModel", "AxisParams", "DriveFirmware", "FirmwareReject"]
