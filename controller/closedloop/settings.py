"""The ``[closedloop]`` table: the panel-mounted closed loop (docs/fisheye.md).

Each tracker listed carries a camera on its panel, looking along the normal (the mounting
convention of :mod:`.geometry`); every control cycle its frame gives the sun's offset from
the normal, and a fuzzy PID per axis moves the setpoint (:mod:`.axis`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

from ..schema import Where, setting

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
    calibration: Path = setting(
        doc="The panel cameras' lens bundle (fisheye TOML without [orientation]; docs/fisheye.md).",
        path="file",
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
        try:
            spec = self.frames.format(tracker="x")
        except (KeyError, IndexError, ValueError):
            raise at.child("frames").error(
                'a camera address whose only field is "{tracker}" (write other braces twice)', self.frames
            ) from None
        if self.frames == "hil" or spec.startswith("device:") or "://" in spec:
            return self
        folder = Path(self.frames).expanduser()
        if not folder.is_absolute():
            folder = at.folder / folder  # not resolved: "{tracker}" need not exist yet
        return replace(self, frames=str(folder))

    def camera(self, tracker: str) -> str:
        """The frames of ``tracker``'s panel camera (``frames`` with its name filled in)."""
        return self.frames.format(tracker=tracker)
