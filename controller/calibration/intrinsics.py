"""Intrinsics from checkerboard images (cv2.calibrateCamera), with reprojection RMS."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from .camera import CameraCal


@dataclass
class IntrinsicsResult:
    camera: CameraCal
    rms_px: float
    used: list[str]
    rejected: list[str]


def find_corners(img: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(img, pattern, flags=flags)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    return cv2.cornerSubPix(img, corners, (5, 5), (-1, -1), crit)


def calibrate_intrinsics(
    images: list, pattern: tuple[int, int], square: float, names: list[str] | None = None
) -> IntrinsicsResult:
    """``images``: grey arrays or paths.  Needs >= 3 views with the whole board found."""
    names = names or [str(i) for i in range(len(images))]
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0 : pattern[0], 0 : pattern[1]].T.reshape(-1, 2) * square
    obj[:, :2] += square  # inner corner (0,0) sits one square in from the board's corner
    objp, imgp, used, rejected = [], [], [], []
    size = None
    for im, nm in zip(images, names):
        if isinstance(im, (str, Path)):
            im = cv2.imread(str(im), cv2.IMREAD_GRAYSCALE)
            if im is None:
                rejected.append(nm)
                continue
        if size is None:
            size = im.shape[::-1]
        elif im.shape[::-1] != size:
            raise InputError(f"{nm}: image size {im.shape[::-1]} differs from {size}")
        c = find_corners(im, pattern)
        if c is None:
            rejected.append(nm)
            continue
        objp.append(obj)
        imgp.append(c)
        used.append(nm)
    if len(objp) < 3:
        raise InputError(
            f"intrinsics need >= 3 checkerboard views with all {pattern[0]}x{pattern[1]} "
            f"inner corners found; found {len(objp)} (rejected: {', '.join(rejected) or '-'})"
        )
    assert size is not None  # at least three views were read
    rms, K, dist, _, _ = cv2.calibrateCamera(objp, imgp, size, None, None)
    d = dist.ravel()[:5]
    cam = CameraCal(
        width=size[0],
        height=size[1],
        fx=float(K[0, 0]),
        fy=float(K[1, 1]),
        cx=float(K[0, 2]),
        cy=float(K[1, 2]),
        dist=tuple(float(x) for x in d),
        rms_px=float(rms),
    )
    return IntrinsicsResult(cam, float(rms), used, rejected)
