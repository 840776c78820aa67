"""Calibration chain of the hotspot sensor: intrinsics, surface model, exterior orientation,
levelling, azimuth alignment, and the bundle TOML that the estimator reads."""

from .bundle import (
    AzimuthCal,
    CalibrationBundle,
    LevelCal,
    LobeCal,
    PoseCal,
    SurfaceCal,
    load_bundle,
    save_bundle,
)
from .camera import CameraCal

__all__ = [
    "AzimuthCal",
    "CalibrationBundle",
    "CameraCal",
    "LevelCal",
    "LobeCal",
    "PoseCal",
    "SurfaceCal",
    "load_bundle",
    "save_bundle",
]
