"""Exterior orientation by PnP: EPnP start, Levenberg-Marquardt refinement (OpenCV), on base
markers detected automatically (ArUco) or picked by hand (CSV)."""

from __future__ import annotations

import csv
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from .camera import CameraCal


@dataclass
class PoseResult:
    rvec: np.ndarray
    tvec: np.ndarray
    rms_px: float
    n_points: int
    model_points: np.ndarray | None = None
    image_points: np.ndarray | None = None


#: The largest reprojection RMS a pose may have (px): a good one is under 1 px.
MAX_RMS_PX = 10.0


def solve_pose(model_pts: np.ndarray, image_pts: np.ndarray, cam: CameraCal) -> PoseResult:
    model_pts = np.ascontiguousarray(np.asarray(model_pts, np.float64).reshape(-1, 1, 3))
    image_pts = np.ascontiguousarray(np.asarray(image_pts, np.float64).reshape(-1, 1, 2))
    if len(model_pts) < 4:
        raise InputError(f"pose needs >= 4 marker points, got {len(model_pts)}")
    # EPnP start (the paper uses DLT); planar marker sets are ambiguous for EPnP, so SQPnP
    # and, when coplanar, IPPE starts are tried too; each is refined by Levenberg-Marquardt
    # and the smallest reprojection RMS wins.
    starts = [cv2.SOLVEPNP_EPNP, cv2.SOLVEPNP_SQPNP]
    if np.ptp(model_pts[:, 0, 2]) < 1e-6:
        starts.append(cv2.SOLVEPNP_IPPE)
    best = None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200, 1e-12)
    for flag in starts:
        try:
            ok, rvec, tvec = cv2.solvePnP(model_pts, image_pts, cam.K, cam.dist_array, flags=flag)
        except cv2.error:
            continue
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(model_pts, image_pts, cam.K, cam.dist_array, rvec, tvec, crit)
        proj, _ = cv2.projectPoints(model_pts, rvec, tvec, cam.K, cam.dist_array)
        rms = float(np.sqrt(np.mean(np.sum((proj - image_pts) ** 2, axis=2))))
        if best is None or rms < best[0]:
            best = (rms, rvec, tvec)
    if best is None:
        raise InputError("PnP failed on the marker points")
    rms, rvec, tvec = best
    if not rms <= MAX_RMS_PX:  # (NaN too) points mismatched, in another unit, or another image
        raise InputError(
            f"pose: the markers reproject {rms:.1f} px RMS from where they were seen (at most "
            f"{MAX_RMS_PX:g}): check the survey's units (m), its ids and the image"
        )
    return PoseResult(
        rvec.ravel(), tvec.ravel(), rms, len(model_pts), model_pts.reshape(-1, 3), image_pts.reshape(-1, 2)
    )


def read_marker_survey(path) -> dict[tuple[int, int], np.ndarray]:
    """CSV ``id,corner,x,y,z`` (model frame, metres) -> {(id, corner): xyz}."""
    out = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                out[(int(row["id"]), int(row["corner"]))] = np.array(
                    [float(row["x"]), float(row["y"]), float(row["z"])]
                )
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"{path}: expected CSV columns id,corner,x,y,z ({exc})") from None
    return out


def read_picked(path) -> tuple[np.ndarray, np.ndarray]:
    """Hand-picked CSV ``x,y,z,u,v`` per row."""
    try:
        a = np.loadtxt(path, delimiter=",", ndmin=2, skiprows=1)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: expected CSV header + rows x,y,z,u,v ({exc})") from None
    if a.shape[1] != 5:
        raise InputError(f"{path}: expected 5 columns x,y,z,u,v")
    return a[:, :3], a[:, 3:]


def detect_markers(img: np.ndarray, survey: dict, dictionary=cv2.aruco.DICT_4X4_50):
    det = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(dictionary), cv2.aruco.DetectorParameters()
    )
    params = det.getDetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    det.setDetectorParameters(params)
    corners, ids, _ = det.detectMarkers(img)
    mp, ip = [], []
    if ids is None:
        return np.zeros((0, 3)), np.zeros((0, 2))
    for c, i in zip(corners, ids.ravel()):
        for k in range(4):
            key = (int(i), k)
            if key in survey:
                mp.append(survey[key])
                ip.append(c.reshape(4, 2)[k])
    return np.array(mp).reshape(-1, 3), np.array(ip).reshape(-1, 2)
