"""The control mode machine: which kind of setpoint the trackers get this cycle.

Priorities follow commercial practice: MANUAL (an operator's setpoint) > night stow >
DIFFUSE (overcast) > TRACK.  Night STOW comes from the sun's elevation, with a small wake
margin so that trackers are already on the sunrise azimuth when the sun clears the horizon;
DIFFUSE from the sky switch (:mod:`controller.diffuse`).  TRACK follows the sun estimate
whatever its source (observed, predicted through a cloud gap, or the ephemeris): the source
is recorded with every setpoint.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class ControlMode(str, Enum):
    TRACK = "TRACK"  # follow the sun estimate (observed, predicted or ephemeris)
    DIFFUSE = "DIFFUSE"  # overcast: the orientation that maximises diffuse light
    STOW = "STOW"  # safe position (night, wind, fault, lost link)
    MANUAL = "MANUAL"  # operator setpoints


@dataclass(frozen=True)
class ModeDecision:
    mode: ControlMode
    reason: str


def decide_mode(
    sun_el_deg: float, min_elevation_deg: float = 0.0, wake_margin_deg: float = 2.0, overcast: bool = False
) -> ModeDecision:
    """Pick the mode for this cycle.

    Parameters
    ----------
    sun_el_deg : float
        Estimated apparent sun elevation at the setpoint time, degrees.
    min_elevation_deg : float
        Below this the sun is not worth tracking, degrees.
    wake_margin_deg : float
        Start tracking this far below ``min_elevation_deg`` (pre-positioning), degrees.
    overcast : bool
        The sky switch says overcast: face the sky dome instead of the hidden sun.
    """
    if sun_el_deg < min_elevation_deg - wake_margin_deg:
        return ModeDecision(ControlMode.STOW, "night")
    if overcast:
        return ModeDecision(ControlMode.DIFFUSE, "overcast")
    return ModeDecision(ControlMode.TRACK, "sun up")
