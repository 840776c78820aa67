"""Axis targets for every tracker in one cycle, from the mode and the sun estimate.

Single-axis rows are computed together in one vectorised pvlib call; every target then
passes :func:`~controller.safety.clamp_targets` on its way to the wire.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .config import DualAxisTracker, SingleAxisTracker, TrackerConfig
from .drives.base import DriveState
from .geometry import dual_axis_setpoint, single_axis_setpoints, wrap_into_range
from .modes import ControlMode
from .sun.types import SunEstimate

Setpoint = tuple[list[float], bool]  # axis targets (deg), backtracking


def tracking(
    est: SunEstimate,
    trackers: Sequence[TrackerConfig],
    states: Sequence[DriveState | None],
    seam_deg: float | None = None,
) -> list[Setpoint]:
    """Follow the sun: dual-axis trackers point at it, rows track with backtracking.

    ``states`` (the drives' last states) keep a dual-axis azimuth on the near side of a
    wrap; ``seam_deg`` (:func:`~controller.geometry.lowest_sun_azimuth`) is where a travel
    wider than one turn unwinds.  A row whose sun is below the horizon (NaN rotation) is
    sent to its stow.
    """
    out: list[Setpoint] = [(list(cfg.stow_angles), False) for cfg in trackers]
    if not (math.isfinite(est.az_deg) and math.isfinite(est.el_deg)):
        return out  # not a direction (a NaN or infinite estimate): nothing to follow
    rows = [(i, cfg) for i, cfg in enumerate(trackers) if isinstance(cfg, SingleAxisTracker)]
    if rows:
        sps = single_axis_setpoints(est.az_deg, est.el_deg, [cfg for _, cfg in rows])
        for (i, _), sp in zip(rows, sps):
            if not math.isnan(sp.rotation_deg):
                out[i] = ([sp.rotation_deg], sp.backtracking)
    for i, cfg in enumerate(trackers):
        if isinstance(cfg, DualAxisTracker):
            st = states[i]
            current = st.axes[0].actual_deg if st is not None else None
            az, el = dual_axis_setpoint(
                est.az_deg, est.el_deg, cfg.azimuth_limits, cfg.elevation_limits, current, seam_deg
            )
            out[i] = ([az, el], False)
    return out


def facing_sky(cfg: TrackerConfig, state: DriveState | None) -> Setpoint:
    """DIFFUSE: flat, the panel faces the zenith and sees the whole overcast dome."""
    if not isinstance(cfg, DualAxisTracker):
        return [0.0], False
    az = state.axes[0].actual_deg if state is not None else cfg.stow[0]
    return [az, min(90.0, cfg.elevation_limits[1])], False


def for_mode(
    mode: ControlMode,
    est: SunEstimate | None,
    trackers: Sequence[TrackerConfig],
    states: Sequence[DriveState | None],
    seam_deg: float | None = None,
) -> list[Setpoint]:
    """Targets of every tracker for ``mode`` (STOW: each tracker's configured stow;
    ``seam_deg`` as for :func:`tracking`)."""
    if mode == ControlMode.DIFFUSE:
        return [facing_sky(cfg, st) for cfg, st in zip(trackers, states)]
    if mode == ControlMode.TRACK and est is not None:
        return tracking(est, trackers, states, seam_deg)
    return [(list(cfg.stow_angles), False) for cfg in trackers]


def manual(
    cfg: TrackerConfig, state: DriveState | None, el_deg: float | None, az_deg: float | None
) -> tuple[float, ...]:
    """An operator's setpoint (SunSpec model 601 semantics), inside the tracker's limits.

    Dual-axis: elevation and azimuth; single-axis: the rotation in ``el_deg``.  A missing
    (or non-finite) value keeps the axis where it is.
    """
    now = state.axes if state is not None else None

    def pick(v: float | None, axis: int, stow: float) -> float:
        if v is not None and math.isfinite(v):
            return float(v)
        return now[axis].actual_deg if now else stow

    if isinstance(cfg, SingleAxisTracker):
        rot = pick(el_deg, 0, cfg.stow)
        return (min(max(rot, -cfg.max_angle), cfg.max_angle),)
    assert isinstance(cfg, DualAxisTracker)
    az = wrap_into_range(
        pick(az_deg, 0, cfg.stow[0]), *cfg.azimuth_limits, near=now[0].actual_deg if now else None
    )
    el = pick(el_deg, 1, cfg.stow[1])
    lo, hi = cfg.elevation_limits
    return az, min(max(el, lo), hi)
