"""The camera on a tracker's panel (paper 003's use of the sky camera): the world's side.

The camera rides on the panel and looks along its normal.  Its orientation follows the
drive's true output angles plus the row's mounting offset
(:meth:`hil.drive.DriveFirmware.panel_angles`), and :func:`hil.skycam.render_sky` draws
what it sees at the simulated time with the scenario's clouds.  Written without the
controller: the mounting convention below is a mechanical fact the controller is told
about (``controller.closedloop.geometry``), computed here from the world's own geometry
(:mod:`hil.truth`) so that a sign error on either side shows up as pointing error.

Mounting (camera frame: OpenCV, x right, y down, z along the optical axis):

* dual-axis (azimuth over elevation) panel at (``az``, ``el``): z is the normal, image x
  runs towards increasing azimuth (horizontal), ``y = z x x`` (down the panel);
* single-axis row at rotation ``rot``: z is the normal, image x runs across the row
  towards increasing rotation (the normal's derivative with the rotation), ``y = z x x``.

That is the panel's frame; a camera mounted off it (``mount_deg``, a rotation vector in
that frame: ``[[hil.mount_offsets]] camera_deg``) is turned by it on the panel.

Angles in degrees, azimuth clockwise from north; ENU vectors (x East, y North, z Up).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from . import truth
from .camera.scene import Site
from .skycam import CloudField, render_sky, seed_lens, sky_profile
from .skycam.scene import Matrix3


def _frame(z: np.ndarray, dz: np.ndarray) -> np.ndarray:
    """``enu_from_camera`` with optical axis ``z`` and image x along ``dz`` (made normal)."""
    z = z / np.linalg.norm(z)
    x = dz - np.dot(dz, z) * z
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z], axis=1)


def dual_axis_camera(az_deg: float, el_deg: float) -> np.ndarray:
    """``enu_from_camera`` (3 x 3, columns: camera x, y, z in ENU) of the camera on a
    dual-axis panel whose normal points at (``az_deg``, ``el_deg``)."""
    h = 1e-3
    z = truth.unit_from_azel(az_deg, el_deg)
    dz = truth.unit_from_azel(az_deg + h, el_deg) - truth.unit_from_azel(az_deg - h, el_deg)
    if np.linalg.norm(dz) < 1e-9:  # the normal at the zenith: x towards the azimuth's east
        a = np.radians(az_deg)
        dz = np.array([np.cos(a), -np.sin(a), 0.0])
    return _frame(z, dz)


def row_camera(rotation_deg: float, axis_azimuth: float, axis_tilt: float) -> np.ndarray:
    """``enu_from_camera`` of the camera on a single-axis row at ``rotation_deg``."""
    h = 1e-3
    z = truth.row_normal(rotation_deg, axis_azimuth, axis_tilt)
    dz = truth.row_normal(rotation_deg + h, axis_azimuth, axis_tilt) - truth.row_normal(
        rotation_deg - h, axis_azimuth, axis_tilt
    )
    return _frame(np.asarray(z, float), np.asarray(dz, float))


def panel_from_camera(mount_deg: tuple[float, float, float]) -> np.ndarray:
    """The camera's rotation on its panel: the rotation vector ``mount_deg`` (deg) in the
    panel's frame (the frame of a camera mounted exactly, above), as a matrix whose columns
    are the camera's axes in that frame."""
    return Rotation.from_rotvec(np.radians(np.asarray(mount_deg, float))).as_matrix()


def panel_lens(scale: float = 0.5):
    """The panel camera's lens: the paper's 190-deg fisheye (640 x 480) at ``scale`` times
    its pixels per side (0.5: 320 x 240, ~1.45 px/deg at the centre, the sun's saturated
    glare ~4.6 px in radius)."""
    return seed_lens().scaled(scale, name=f"panel-seed-x{scale:g}")


@dataclass
class PanelCamera:
    """One panel's camera: ``render(t, angles, transmittance)`` -> BGR uint8 image.

    ``kind``: ``"dual-axis"`` or ``"single-axis"``; ``axis_azimuth``/``axis_tilt``: the
    row's geometry (single-axis); ``angles``: the panel's true angles (deg, with the
    mounting offset: ``DriveFirmware.panel_angles()``); ``transmittance``: the clouds' beam
    transmittance over the sun (0: hidden, 1: clear); ``clouds``: the cloud layer drawn in
    the frame (None: a clear sky), the one the sky camera draws; ``distractors``: glares
    that are not the sun (:mod:`hil.skycam.distractors`), such as a fixed reflection.
    """

    kind: str
    site: Site
    axis_azimuth: float = 180.0
    axis_tilt: float = 0.0
    scale: float = 0.5
    noise: bool = True
    clouds: CloudField | None = None
    distractors: tuple = ()  # hil.skycam.distractors: SpecularReflection, AircraftGlint, ...
    mount_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the camera's rotation on the panel

    def __post_init__(self) -> None:
        self.scene = sky_profile("seed", noise=self.noise).with_(
            lens=panel_lens(self.scale), site=self.site, clouds=self.clouds, distractors=self.distractors
        )

    def enu_from_camera(self, angles: list[float]) -> np.ndarray:
        if self.kind == "dual-axis":
            enu_from_panel = dual_axis_camera(angles[0], angles[1])
        else:
            enu_from_panel = row_camera(angles[0], self.axis_azimuth, self.axis_tilt)
        return enu_from_panel @ panel_from_camera(self.mount_deg)

    def render(self, t: float, angles: list[float], transmittance: float) -> np.ndarray:
        R = self.enu_from_camera(angles)
        m: Matrix3 = tuple(tuple(float(v) for v in row) for row in R)  # type: ignore[assignment]
        scn = self.scene.with_(enu_from_camera=m)
        T = float(min(max(transmittance, 0.0), 1.0))
        return render_sky(scn, t, sun_transmittance=T).image

    def source(
        self, angles: Callable[[], list[float]], transmittance: Callable[[float], float]
    ) -> Callable[[float], np.ndarray]:
        """``render(t)`` for a frame source: the panel's angles and the clouds read at ``t``."""
        return lambda t: self.render(t, angles(), transmittance(t))


def write_commissioning(
    cam: PanelCamera,
    folder: Path,
    held: list[list[float]],
    *,
    start: float,
    frames: int = 36,
    step_s: float = 900.0,
    inclinometer_deg: float = 0.02,
    seed: int = 3,
) -> Path:
    """What an installer collects to measure a panel camera's mount: ``frames`` frames
    every ``step_s`` from POSIX ``start`` (a clear sky), the panel held at each of ``held``
    in turn (its true angles, deg), written as ``<time>.png`` into ``folder``, and the
    panel's angles as an inclinometer reads them (``inclinometer_deg`` of noise) into
    ``folder/angles.csv`` (``time`` and one column per axis).  Returns the CSV's path."""
    from .skycam.dataset import frame_name

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    axes = "azimuth,elevation" if cam.kind == "dual-axis" else "rotation"
    lines = [f"time,{axes}"]
    for k in range(frames):
        t = start + k * step_s
        angles = held[k % len(held)]
        cv2.imwrite(str(folder / frame_name(t)), cam.render(t, angles, 1.0))
        read = ",".join(f"{a + rng.normal(scale=inclinometer_deg):.3f}" for a in angles)
        lines.append(f"{datetime.fromtimestamp(t, UTC).isoformat()},{read}")
    out = folder / "angles.csv"
    out.write_text("\n".join(lines) + "\n")
    return out
