"""The camera's intrinsics, as a calibration bundle's ``[camera]`` table.

OpenCV conventions: pinhole with Brown-Conrady ``dist = [k1, k2, p1, p2, k3]`` (also 4, 8,
12 or 14 coefficients), or ``model = "fisheye"`` (Kannala-Brandt, ``cv2.fisheye``,
``dist = [k1, k2, k3, k4]``).  Pixels, with (0, 0) the centre of the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..schema import Where, setting

#: Distortion vector lengths OpenCV accepts, per model.
DIST_LENGTHS = {"pinhole": (4, 5, 8, 12, 14), "fisheye": (4,)}


_DEFAULT_DIST = (0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CameraCal:
    """Intrinsics of the camera (OpenCV)."""

    width: int = setting(doc="Image width.", unit="px", ge=1, le=100_000)
    height: int = setting(doc="Image height.", unit="px", ge=1, le=100_000)
    fx: float = setting(doc="Focal length along x.", unit="px", gt=0)
    fy: float = setting(doc="Focal length along y.", unit="px", gt=0)
    cx: float = setting(doc="Principal point x.", unit="px")
    cy: float = setting(doc="Principal point y.", unit="px")
    dist: tuple[float, ...] = setting(
        _DEFAULT_DIST,
        doc="Distortion "
        "coefficients in OpenCV's order: [k1, k2, p1, p2, k3] "
        "(pinhole), [k1, k2, k3, k4] (fisheye).",
    )
    rms_px: float | None = setting(
        None, doc="Reprojection RMS of the intrinsic calibration.", unit="px", ge=0
    )
    model: Literal["pinhole", "fisheye"] = setting(
        "pinhole", doc="Lens model: pinhole + Brown-Conrady, or cv2.fisheye (Kannala-Brandt)."
    )

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, float)

    def __schema_check__(self, at: Where) -> CameraCal:
        if len(self.dist) not in DIST_LENGTHS[self.model]:
            order = "[k1, k2, k3, k4]" if self.model == "fisheye" else "[k1, k2, p1, p2, k3]"
            got = (
                "the pinhole's default (is the key missing?)"
                if self.dist == _DEFAULT_DIST
                else list(self.dist)
            )
            raise at.child("dist").error(f"{order} (OpenCV order, {self.model} model)", got)
        for key, c, size in (("cx", self.cx, self.width), ("cy", self.cy, self.height)):
            if not 0 <= c <= size:  # the lens's axis meets the sensor (a sign or a unit error does not)
                raise at.child(key).error(f"a principal point inside the {size}-px image", c)
        return self
