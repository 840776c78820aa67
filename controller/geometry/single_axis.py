"""Single-axis rows: true tracking and slope-aware backtracking via pvlib.

The rotation angle follows pvlib's ``tracking.singleaxis`` (right-handed about the axis
pointing along ``axis_azimuth`` and tilted up by ``axis_tilt``; for a north-south row,
positive turns the panel to face west).  Backtracking is Anderson & Mikofski (2020),
including the cross-axis slope.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pvlib


@dataclass(frozen=True)
class SingleAxisSetpoint:
    """Result for one instant (degrees).

    ``rotation_deg`` is the setpoint; ``true_tracking_deg`` what it would be without
    backtracking; ``backtracking`` True when they differ; ``aoi_deg`` the angle of incidence
    at the setpoint.  ``rotation_deg`` is NaN when the sun is below the horizon.
    """

    rotation_deg: float
    true_tracking_deg: float
    backtracking: bool
    aoi_deg: float


def single_axis_setpoint(sun_az_deg, sun_el_deg, *, axis_azimuth: float = 180.0,
                         axis_tilt: float = 0.0, max_angle: float = 55.0, gcr: float = 0.4,
                         cross_axis_tilt: float = 0.0, backtrack: bool = True
                         ) -> SingleAxisSetpoint:
    """Rotation setpoint of a single-axis row for a sun direction (degrees).

    Parameters
    ----------
    sun_az_deg, sun_el_deg : float
        Sun azimuth (clockwise from north) and apparent elevation, degrees.
    axis_azimuth : float
        Compass direction the axis points to, degrees (180: north-south row).
    axis_tilt : float
        Axis tilt above horizontal, degrees (slope along the row).
    max_angle : float
        Rotation limit, degrees (symmetric).
    gcr : float
        Ground coverage ratio (collector width / row pitch).
    cross_axis_tilt : float
        Slope across the rows, degrees (pvlib's sign convention).
    backtrack : bool
        Avoid row-to-row shading when the sun is low.
    """
    zen = 90.0 - float(sun_el_deg)
    kw = dict(apparent_zenith=np.array([zen]), solar_azimuth=np.array([float(sun_az_deg)]),
              axis_tilt=axis_tilt, axis_azimuth=axis_azimuth, max_angle=max_angle,
              gcr=gcr, cross_axis_tilt=cross_axis_tilt)
    bt = pvlib.tracking.singleaxis(backtrack=backtrack, **kw)
    tt = pvlib.tracking.singleaxis(backtrack=False, **kw)
    rot = float(np.asarray(bt["tracker_theta"])[0])
    true = float(np.asarray(tt["tracker_theta"])[0])
    aoi = float(np.asarray(bt["aoi"])[0])
    backtracking = bool(backtrack and not (math.isnan(rot) or abs(rot - true) < 1e-9))
    return SingleAxisSetpoint(rot, true, backtracking, aoi)
