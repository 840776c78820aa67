"""Sky type from a pyranometer: fractal dimension, clearness index and sunshine (paper 002).

Entry points: :func:`classify_days` (a station record, one class per day) and
:func:`classify_window` (the controller's rolling window).  See docs/skytype.md.
"""

from .classify import CLASS_NAMES, DayResults, WindowClass, classify_days, classify_window
from .fractal import PAPER_SCALES_S, variation_dimension
from .settings import SkyConfig, SkySettings

__all__ = [
    "CLASS_NAMES",
    "DayResults",
    "SkyConfig",
    "SkySettings",
    "WindowClass",
    "classify_days",
    "classify_window",
    "PAPER_SCALES_S",
    "variation_dimension",
]
