"""A row's pose and its panel camera's sun: per-axis errors from a sighting, the axis angles
that face the sun, and where the sun must lie in the camera for a drive's position.

Angles in degrees; errors are sun minus boresight (:mod:`.geometry` holds the conventions).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..geometry import single_axis_setpoints
from ..sun.types import SunEstimate, azel_to_enu
from ..trackers import DualAxisTracker, SingleAxisTracker, TrackerConfig
from ..vision.fisheye.gates import CameraPrior
from .axis import ClosedLoopAxis
from .geometry import dual_axis_enu_from_camera, dual_axis_errors, row_enu_from_camera, single_axis_error


def axis_names(cfg: TrackerConfig) -> tuple[str, ...]:
    """The names of a tracker's axes in the misalignment store."""
    return ("azimuth", "elevation") if isinstance(cfg, DualAxisTracker) else ("rotation",)


def unclipped_reference(cfg: TrackerConfig, sun: SunEstimate) -> list[float] | None:
    """A row's reference (deg, backtracking included) with no rotation limit: where its
    panel should face.  The limit is the drive's, so a row whose panel sits off its shaft
    is clipped only once the learned offset is added (a panel 1.5 deg off reaches a sun
    1.5 deg past ``max_angle`` on one side); None for a dual-axis tracker, whose reference
    is clipped by its elevation limits only where no sun is, or for no sun."""
    if not isinstance(cfg, SingleAxisTracker) or not (
        math.isfinite(sun.az_deg) and math.isfinite(sun.el_deg)
    ):
        return None
    (ref,) = single_axis_setpoints(sun.az_deg, sun.el_deg, [replace(cfg, max_angle=90.0)])
    return [ref.rotation_deg] if math.isfinite(ref.rotation_deg) else None


def sun_angles(cfg: TrackerConfig, sun: SunEstimate, position: list[float]) -> list[float]:
    """The axis angles (deg) that face ``sun``, with no limit, backtracking or travel
    applied: a row's, the sun's angle in its rotation plane; a dual-axis tracker's, the
    sun's azimuth (within half a turn of the drive's ``position``) and elevation.  What a
    camera's error measures the offset against while the row looks elsewhere."""
    if isinstance(cfg, DualAxisTracker):
        return [position[0] + (sun.az_deg - position[0] + 180.0) % 360.0 - 180.0, sun.el_deg]
    assert isinstance(cfg, SingleAxisTracker)
    flat = row_enu_from_camera(0.0, cfg.axis_azimuth, cfg.axis_tilt)  # the row at rotation 0
    return [single_axis_error(flat.T @ azel_to_enu(sun.az_deg, sun.el_deg))]


def camera_errors(cfg: TrackerConfig, d_cam: Any, position: list[float]) -> list[float]:
    """Per-axis errors (deg, sun minus boresight) of the sun's camera-frame direction."""
    if isinstance(cfg, DualAxisTracker):
        return list(dual_axis_errors(d_cam, position[0], position[1]))
    return [single_axis_error(d_cam)]


def expected_sun(
    cfg: TrackerConfig,
    sun: SunEstimate,
    position: list[float],
    axes: list[ClosedLoopAxis],
    mount: np.ndarray | None = None,
) -> CameraPrior:
    """Where the sun ``sun`` lies in the panel camera's frame for a drive at ``position``
    (deg), the panel sitting off it by minus each axis's learned offset and the camera on
    the panel by ``mount`` (its bundle's ``panel_from_camera``; None: along the normal); its
    sigma (deg) that of the learned offsets together."""
    panel = [p - ax.learner.estimate_deg for p, ax in zip(position, axes)]
    if isinstance(cfg, DualAxisTracker):
        enu_from_camera = dual_axis_enu_from_camera(panel[0], panel[1])
    else:
        assert isinstance(cfg, SingleAxisTracker)
        enu_from_camera = row_enu_from_camera(panel[0], cfg.axis_azimuth, cfg.axis_tilt)
    d_cam = enu_from_camera.T @ azel_to_enu(sun.az_deg, sun.el_deg)
    if mount is not None:
        d_cam = mount.T @ d_cam
    sigma = math.sqrt(sum(ax.learner.variance for ax in axes) + sun.sigma_deg**2)
    return CameraPrior(d_cam, sigma)
