"""Tracker geometry: from a sun direction to axis setpoints."""

from .dual_axis import dual_axis_setpoint, lowest_sun_azimuth, wrap_into_range
from .single_axis import RowGeometry, SingleAxisSetpoint, single_axis_setpoint, single_axis_setpoints

__all__ = [
    "RowGeometry",
    "SingleAxisSetpoint",
    "dual_axis_setpoint",
    "lowest_sun_azimuth",
    "single_axis_setpoint",
    "single_axis_setpoints",
    "wrap_into_range",
]
