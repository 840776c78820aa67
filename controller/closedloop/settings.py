"""The ``[closedloop]`` table: the panel-mounted closed loop (docs/fisheye.md).

Each tracker listed carries a camera on its panel, looking along the normal (the mounting
convention of :mod:`.geometry`); every control cycle its frame gives the sun's offset from
the normal, and a fuzzy PID per axis moves the setpoint (:mod:`.axis`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

from ..schema import Where, checked_path, setting

#: The placeholder of ``[closedloop] frames`` that names each tracker's own camera.
TRACKER_FIELD = "{tracker}"

ClosedLoopMode = Literal["assisted", "paper"]


@dataclass(frozen=True, kw_only=True)
class ClosedLoopConfig:
    """The panel-mounted closed loop (the sun's offset in a camera on each panel)."""

    enabled: bool = setting(True, doc="Drive the listed trackers in closed loop.")
    mode: ClosedLoopMode = setting(
        "assisted",
        doc='"paper": the camera alone (the setpoint holds when the sun is not seen); '
        "\"assisted\": the sun source's reference plus the row's learned offset plus the "
        "fuzzy PID's correction (the offset is kept through cloud gaps).",
    )
    calibration: str = setting(
        doc="The panel cameras' lens bundle (fisheye TOML without [orientation]; docs/fisheye.md), "
        "or with \"{tracker}\" standing for the tracker's name, each camera's own (e.g. "
        '"calibration/panel-{tracker}.toml"; a camera\'s principal point is its boresight, and '
        "one pixel off at 320 x 240 points the panel about 0.7 deg off: calibrate each at 640 x 480 "
        "or more). Relative paths are "
        "from this file's folder.",
        nonempty=True,
        example='"calibration/panel-fisheye.toml"',
    )
    algorithm: Literal["default", "seed"] = setting(
        "default",
        doc='The panel cameras\' pipeline: "default" (ours: the rim on the sphere, gates), or '
        "\"seed\" (the paper's HSI segmentation and three rules); the paper's own loop is "
        'mode = "paper" with algorithm = "seed".',
    )
    frames: str = setting(
        "hil",
        doc='Where the panel cameras\' frames come from: "hil" (rendered by the simulator), or '
        'for `heliotrack run` each camera\'s folder of timestamped images, "device:N" or '
        'stream URL, with "{tracker}" standing for the tracker\'s name (e.g. '
        '"/srv/panelcams/{tracker}"; needed when several trackers are in the loop). A frame is '
        "used only if it was taken after the row's last setpoint. Relative paths are from "
        "this file's folder.",
        nonempty=True,
    )
    trackers: tuple[str, ...] = setting((), doc="Trackers with a panel camera (empty: every tracker).")
    state: Path | None = setting(
        None, doc="File where the learned row offsets persist (none: not persisted).", path="new"
    )
    max_error_deg: float = setting(
        60.0,
        doc="A camera error larger than this (deg, per axis) is not trusted (assisted mode).",
        unit="deg",
        gt=0,
        le=90,
    )
    max_offset_deg: float = setting(
        5.0,
        doc="The largest misalignment the assisted loop learns, per axis: a frame that would "
        "measure more is no sight of the sun (a reflection that stays lit while a cloud hides "
        "the sun), and is not used.",
        unit="deg",
        gt=0,
        le=30,
    )

    def __schema_check__(self, at: Where) -> ClosedLoopConfig:
        spec = _fill(self.frames, at.child("frames"), "a camera address")
        _fill(self.calibration, at.child("calibration"), "a bundle's path")
        # with "{tracker}", each looped tracker's bundle is checked with the trackers (Config)
        kind = "" if TRACKER_FIELD in self.calibration else "file"
        calibration = str(checked_path(self.calibration, at.child("calibration"), kind))
        if self.frames == "hil" or spec.startswith("device:") or "://" in spec:
            return replace(self, calibration=calibration)
        # not resolved: "{tracker}" need not exist yet
        return replace(self, frames=str(_from_folder(self.frames, at)), calibration=calibration)

    def camera(self, tracker: str) -> str:
        """The frames of ``tracker``'s panel camera (``frames`` with its name filled in)."""
        return self.frames.format(tracker=tracker)

    def lens(self, tracker: str) -> Path:
        """The lens bundle of ``tracker``'s panel camera (``calibration`` with its name
        filled in)."""
        return Path(self.calibration.format(tracker=tracker))


def _fill(value: str, at: Where, what: str) -> str:
    """``value`` with ``{tracker}`` filled in, or the error that names its other fields."""
    try:
        return value.format(tracker="x")
    except (KeyError, IndexError, ValueError):
        raise at.error(
            f'{what} whose only field is "{TRACKER_FIELD}" (write other braces twice)', value
        ) from None


def _from_folder(value: str, at: Where) -> Path:
    """``value`` as a path, from the configuration file's folder when relative."""
    path = Path(value).expanduser()
    return path if path.is_absolute() else at.folder / path
