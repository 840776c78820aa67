"""From the panel camera's sun direction to each drive axis's error.

Mounting convention (documented, and the bundle's orientation for a panel camera): the
camera's optical axis is the panel's normal.

* Dual-axis (azimuth over elevation) tracker pointing at (``az``, ``el``): image x runs
  towards increasing azimuth (horizontal), image y towards decreasing elevation (down the
  panel), so ``camera_from_enu`` has rows x = (cos az, -sin az, 0),
  y = (sin el sin az, sin el cos az, -cos el), z = the normal.
* Single-axis row: image x runs across the row, towards increasing rotation; y along the
  row's axis.  The rotation error is the sun's angle in the x-z plane, ``atan2(x, z)``,
  whatever the sun's position along the row.

Errors are in degrees, sun minus boresight.
"""

from __future__ import annotations

import math

import numpy as np

from ..sun.types import enu_to_azel


def dual_axis_enu_from_camera(az_deg: float, el_deg: float) -> np.ndarray:
    """``enu_from_camera`` of a camera on a dual-axis panel pointing at (az, el)."""
    a, e = math.radians(az_deg), math.radians(el_deg)
    x = np.array([math.cos(a), -math.sin(a), 0.0])
    z = np.array([math.cos(e) * math.sin(a), math.cos(e) * math.cos(a), math.sin(e)])
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def dual_axis_errors(d_cam: np.ndarray, az_deg: float, el_deg: float) -> tuple[float, float]:
    """(azimuth error, elevation error) in deg for the sun's camera-frame direction ``d_cam``
    seen from a panel pointing at (``az_deg``, ``el_deg``).  Exact, not small-angle."""
    s = dual_axis_enu_from_camera(az_deg, el_deg) @ np.asarray(d_cam, float)
    az, el = enu_to_azel(s)
    return float((az - az_deg + 180.0) % 360.0 - 180.0), float(el - el_deg)


def single_axis_error(d_cam: np.ndarray) -> float:
    """Rotation error (deg) of a single-axis row from the sun's camera-frame direction."""
    d = np.asarray(d_cam, float)
    return math.degrees(math.atan2(d[0], d[2]))


def row_normal(rotation_deg: float, axis_azimuth: float, axis_tilt: float) -> np.ndarray:
    """Unit ENU normal of a single-axis row at ``rotation_deg`` (pvlib's convention for the
    rotation, axis azimuth and tilt: ``pvlib.tracking.calc_surface_orientation``)."""
    from pvlib.tracking import calc_surface_orientation

    o = calc_surface_orientation(rotation_deg, axis_tilt, axis_azimuth)
    tilt = math.radians(float(np.ravel(o["surface_tilt"])[0]))
    az = math.radians(float(np.ravel(o["surface_azimuth"])[0]))
    return np.array([math.sin(tilt) * math.sin(az), math.sin(tilt) * math.cos(az), math.cos(tilt)])


def row_enu_from_camera(rotation_deg: float, axis_azimuth: float, axis_tilt: float) -> np.ndarray:
    """``enu_from_camera`` of a camera on a row at ``rotation_deg`` (columns x, y, z in ENU):
    z the normal, x across the row towards increasing rotation, y = z x x (along the row)."""
    h = 1e-3
    z = row_normal(rotation_deg, axis_azimuth, axis_tilt)
    x = row_normal(rotation_deg + h, axis_azimuth, axis_tilt) - row_normal(
        rotation_deg - h, axis_azimuth, axis_tilt
    )
    x = x - z * float(x @ z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)
