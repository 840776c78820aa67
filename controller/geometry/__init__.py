"""Tracker geometry: from a sun direction to axis setpoints."""

from .dual_axis import dual_axis_setpoint, wrap_into_range
from .single_axis import SingleAxisSetpoint, single_axis_setpoint

__all__ = ["SingleAxisSetpoint", "dual_axis_setpoint", "single_axis_setpoint", "wrap_into_range"]
