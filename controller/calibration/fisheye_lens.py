"""Lens calibration of the fisheye sky camera from checkerboard views (``cv2.fisheye``).

Corners: ``cv2.findChessboardCorners`` then ``cv2.cornerSubPix`` with a small window
(3 px half-size: near the image circle's edge the squares are squeezed to a few pixels and a
larger window reaches the next corner).  Model: ``cv2.fisheye.calibrate`` (Kannala-Brandt
K, D = k1..k4, no skew), started from a guess whose focal length puts 90 deg at a third of
the smaller image side.  OpenCV 5's fisheye calibration wants its points as (1, N, 3) and
(1, N, 2) arrays, and throws when a view is degenerate; such views are dropped one at a
time until it converges.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..errors import InputError
from .camera import CameraCal

_SUBPIX = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
_CALIB = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)


@dataclass
class LensCalibration:
    camera: CameraCal
    rms_px: float
    used: list[str] = field(default_factory=list)
    rejected: dict[str, str] = field(default_factory=dict)


def board_points(pattern: tuple[int, int], square: float) -> np.ndarray:
    """Inner corners (N, 3) in the board frame, row by row (OpenCV's order), metres."""
    nx, ny = pattern
    j, i = np.mgrid[0:ny, 0:nx]
    return np.stack([(i.ravel() + 1) * square, (j.ravel() + 1) * square, np.zeros(nx * ny)], 1)


def find_corners(grey: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """Sub-pixel inner corners (N, 2) of a checkerboard view, or None."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, c = cv2.findChessboardCorners(grey, pattern, flags=flags)
    if not ok:
        return None
    c = cv2.cornerSubPix(grey, c, (3, 3), (-1, -1), _SUBPIX)
    return c.reshape(-1, 2).astype(np.float64)


def calibrate_fisheye(
    views: Sequence[tuple[str, np.ndarray]],
    size: tuple[int, int],
    pattern: tuple[int, int] = (9, 6),
    square: float = 0.04,
    min_views: int = 6,
) -> LensCalibration:
    """Fisheye intrinsics from grey checkerboard views ``[(name, image), ...]`` of ``size``
    (width, height).  Raises :class:`InputError` when too few views are usable."""
    W, H = size
    obj = board_points(pattern, square).reshape(1, -1, 3)
    names, pts, rejected = [], [], {}
    for name, img in views:
        if img.shape[:2] != (H, W):
            rejected[name] = f"size {img.shape[1]}x{img.shape[0]}, expected {W}x{H}"
            continue
        c = find_corners(img, pattern)
        if c is None:
            rejected[name] = "checkerboard not found"
            continue
        names.append(name)
        pts.append(c.reshape(1, -1, 2))
    while len(pts) >= min_views:
        try:
            rms, K, D = _calibrate(obj, pts, (W, H))
            break
        except cv2.error:
            bad = _worst_view(obj, pts, (W, H))
            rejected[names[bad]] = "degenerate for the fisheye calibration"
            del names[bad], pts[bad]
    else:
        raise InputError(
            f"fisheye lens calibration: {len(pts)} usable checkerboard views, "
            f"need >= {min_views} ({len(rejected)} rejected)"
        )
    cam = CameraCal(
        width=W,
        height=H,
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=tuple(float(x) for x in D.ravel()),
        rms_px=float(rms),
        model="fisheye",
    )
    return LensCalibration(camera=cam, rms_px=float(rms), used=names, rejected=rejected)


def _calibrate(obj: np.ndarray, pts: list[np.ndarray], size: tuple[int, int]):
    W, H = size
    f0 = min(W, H) / 3.0
    K = np.array([[f0, 0.0, (W - 1) / 2.0], [0.0, f0, (H - 1) / 2.0], [0.0, 0.0, 1.0]])
    D = np.zeros((4, 1))
    flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW | cv2.CALIB_USE_INTRINSIC_GUESS
    rms, K_out, D_out, _, _ = cv2.fisheye.calibrate(
        [obj] * len(pts), pts, (W, H), K, D, flags=flags, criteria=_CALIB
    )
    return float(rms), np.asarray(K_out, float), np.asarray(D_out, float)


def _worst_view(obj: np.ndarray, pts: list[np.ndarray], size: tuple[int, int]) -> int:
    """The view whose removal lets the calibration run (the first found), else the last."""
    for i in range(len(pts)):
        try:
            _calibrate(obj, pts[:i] + pts[i + 1 :], size)
            return i
        except cv2.error:
            continue
    return len(pts) - 1
