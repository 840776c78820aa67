"""Calibration chain of the hotspot sensor: intrinsics, surface model, exterior orientation,
levelling, azimuth alignment, and the bundle TOML that the estimator reads."""

from .bundle import CalibrationBundle, CameraCal, LevelCal, PoseCal, SurfaceCal, load_bundle, save_bundle

__all__ = ["CalibrationBundle", "CameraCal", "SurfaceCal", "PoseCal", "LevelCal", "load_bundle",
           "save_bundle"]
