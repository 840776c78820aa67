"""The control mode machine: which kind of setpoint the trackers get this cycle.

Priorities follow commercial practice: STOW (wind, snow, operator) > MANUAL > night
stow > DIFFUSE (overcast) > TRACK / PREDICT.  Night STOW comes from the sun's elevation, with a
small wake margin so that trackers are already on the sunrise azimuth when the sun clears
the horizon; DIFFUSE from the sky switch (:mod:`controller.diffuse`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class ControlMode(str, Enum):
    TRACK = "TRACK"        # follow the sun estimate (observed or ephemeris)
    PREDICT = "PREDICT"    # follow the sun-path filter's prediction (cloud gap)
    DIFFUSE = "DIFFUSE"    # overcast: the orientation that maximises diffuse light
    STOW = "STOW"          # safe position (night, wind, fault, lost link)
    MANUAL = "MANUAL"      # operator setpoints


@dataclass(frozen=True)
class ModeDecision:
    mode: ControlMode
    reason: str


def decide_mode(sun_el_deg: float, min_elevation_deg: float = 0.0,
                wake_margin_deg: float = 2.0, forced_stow: str | None = None,
                overcast: bool = False) -> ModeDecision:
    """Pick the mode for this cycle.

    Parameters
    ----------
    sun_el_deg : float
        Estimated apparent sun elevation at the setpoint time, degrees.
    min_elevation_deg : float
        Below this the sun is not worth tracking, degrees.
    wake_margin_deg : float
        Start tracking this far below ``min_elevation_deg`` (pre-positioning), degrees.
    forced_stow : str, optional
        Reason for an override stow (wind, operator...); wins over everything.
    overcast : bool
        The sky switch says overcast: face the sky dome instead of the hidden sun.
    """
    if forced_stow:
        return ModeDecision(ControlMode.STOW, forced_stow)
    if sun_el_deg < min_elevation_deg - wake_margin_deg:
        return ModeDecision(ControlMode.STOW, "night")
    if overcast:
        return ModeDecision(ControlMode.DIFFUSE, "overcast")
    return ModeDecision(ControlMode.TRACK, "sun up")
