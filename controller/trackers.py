"""What a ``[[trackers]]`` table holds: a dual-axis tracker or a single-axis row, and the
drive that moves it (the schema of each tracker type)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from .geometry.single_axis import RowGeometry
from .schema import Where, setting

__all__ = ["TRACKER_CLASSES", "DualAxisTracker", "SingleAxisTracker", "TrackerConfig"]


@dataclass(frozen=True, kw_only=True)
class TrackerConfig:
    """One tracker (dual-axis) or row (single-axis) and the drive that moves it."""

    name: str = setting(doc="Unique name (logs, SunSpec, cycles.csv).", nonempty=True)
    type: str = setting(doc="The tracker type.")
    link: str = setting(doc="Name of the `[[links]]` table the drive is on.")
    device_id: int = setting(
        doc="Modbus slave id, or CANopen node id of axis 0 (axis k is node id + k).", ge=1, le=247
    )
    safe_position: Literal["stow", "hold"] = setting(
        "stow",
        doc="Where `heliotrack run` leaves the drive when it stops (SIGTERM, "
        "SIGINT): its stow position, or holding where it is.",
    )

    axes: ClassVar[int] = 0

    @property
    def soft_limits(self) -> list[tuple[float, float]]:
        """Travel of each axis (degrees), written to the drive as its soft limits."""
        raise NotImplementedError

    @property
    def stow_angles(self) -> tuple[float, ...]:
        """Stow position of each axis, degrees."""
        raise NotImplementedError

    def _check_stow(self, at: Where) -> None:
        for k, (angle, (lo, hi)) in enumerate(zip(self.stow_angles, self.soft_limits)):
            if not lo <= angle <= hi:
                key = at.child("stow") if self.axes == 1 else at.child("stow").item(k)
                raise key.error(f"a stow angle within the axis limits [{lo:g}, {hi:g}] deg", angle)


@dataclass(frozen=True, kw_only=True)
class DualAxisTracker(TrackerConfig):
    """A dual-axis tracker: axis 0 is the azimuth of the panel normal (clockwise from
    north, within ``azimuth_limits``, which may extend past 0/360), axis 1 its elevation."""

    type: Literal["dual-axis"] = setting("dual-axis", doc="Dual-axis tracker.")
    azimuth_limits: tuple[float, float] = setting(
        (0.0, 360.0),
        doc="Azimuth travel [min, max]; its seam must not lie on the sun's path: [-180, 180] "
        "south of the equator (`config validate`, `run` and `simulate` warn). Under a midnight "
        "sun (latitude beyond 65), a travel holding a whole turn from the sun's lowest azimuth "
        "to the next (north: e.g. [-90, 450]; south: [-270, 270]) unwinds there once a day.",
        unit="deg",
        ge=-360,
        le=720,
    )
    elevation_limits: tuple[float, float] = setting(
        (0.0, 90.0), doc="Elevation travel [min, max].", unit="deg", ge=-10, le=100
    )
    stow: tuple[float, float] = setting(
        (180.0, 90.0), doc="Stow position [azimuth, elevation] (90: facing up).", unit="deg", ge=-360, le=720
    )

    axes: ClassVar[int] = 2

    @property
    def soft_limits(self) -> list[tuple[float, float]]:
        return [self.azimuth_limits, self.elevation_limits]

    @property
    def stow_angles(self) -> tuple[float, ...]:
        return self.stow

    def __schema_check__(self, at: Where) -> DualAxisTracker:
        for key in ("azimuth_limits", "elevation_limits"):
            lo, hi = getattr(self, key)
            if not lo < hi:
                raise at.child(key).error("[min, max] with min < max", [lo, hi])
        self._check_stow(at)
        return self


@dataclass(frozen=True, kw_only=True)
class SingleAxisTracker(RowGeometry, TrackerConfig):
    """A single-axis row: axis 0 is pvlib's rotation angle ``tracker_theta`` (right-handed
    about the axis pointing along ``axis_azimuth``; for a north-south row, positive faces
    west); its geometry keys are those of `controller.geometry.RowGeometry`."""

    type: Literal["single-axis"] = setting("single-axis", doc="Single-axis row.")
    stow: float = setting(0.0, doc="Stow rotation (0: flat).", unit="deg", ge=-90, le=90)

    axes: ClassVar[int] = 1

    @property
    def soft_limits(self) -> list[tuple[float, float]]:
        return [(-self.max_angle, self.max_angle)]

    @property
    def stow_angles(self) -> tuple[float, ...]:
        return (self.stow,)

    def __schema_check__(self, at: Where) -> SingleAxisTracker:
        self._check_stow(at)
        return self


TRACKER_CLASSES: dict[str, type[TrackerConfig]] = {
    "dual-axis": DualAxisTracker,
    "single-axis": SingleAxisTracker,
}
