"""Levelling from plumb lines: vertical vanishing point by least squares over all lines,
rotated into the model frame (paper section 2-6-1)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from .camera import CameraCal


@dataclass
class ZenithResult:
    zenith_model: np.ndarray
    vp_cam: np.ndarray  # unit direction of the vanishing point in the camera frame
    n_lines: int
    rms_line_deg: float  # RMS angle between each line's plane and the vanishing direction


def _normalise(pts_px: np.ndarray, cam: CameraCal, undistorted: bool) -> np.ndarray:
    pts = np.asarray(pts_px, np.float64).reshape(-1, 1, 2)
    xy: np.ndarray
    if undistorted:
        xy = (pts.reshape(-1, 2) - [cam.cx, cam.cy]) / [cam.fx, cam.fy]
    else:
        xy = cv2.undistortPoints(
            pts,
            cam.K,
            cam.dist_array,
            None,
            None,
            None,
            (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12),
        ).reshape(-1, 2)
    return xy


def zenith_from_lines(
    lines, cam: CameraCal, rvec, *, undistorted: bool = False, robust: bool = True
) -> ZenithResult:
    """``lines``: sequence of (>= 2, 2) pixel point arrays, one per plumb line."""
    planes, weights = [], []
    for line in lines:
        line = np.asarray(line, float)
        if line.shape[0] < 2:
            raise InputError("each plumb line needs >= 2 points")
        xy = _normalise(line, cam, undistorted)
        rays = np.hstack([xy, np.ones((len(xy), 1))])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        _, _, vt = np.linalg.svd(rays, full_matrices=False)
        planes.append(vt[-1])  # normal of the plane through the camera centre and the line
        # precision of a line's direction grows with its angular length and sqrt(points)
        weights.append(np.degrees(np.arccos(np.clip(rays[0] @ rays[-1], -1, 1))) * np.sqrt(len(rays)))
    if len(planes) < 2:
        raise InputError(f"levelling needs >= 2 plumb lines, got {len(planes)}")
    P = np.array(planes)
    w = np.array(weights) / max(np.median(weights), 1e-12)
    keep = np.ones(len(P), bool)
    while True:  # weighted least squares over all lines, then drop a clear outlier and redo
        _, _, vt = np.linalg.svd(P[keep] * w[keep, None])
        vp = vt[-1]
        resid = np.degrees(np.arcsin(np.clip(np.abs(P @ vp), 0, 1)))
        if keep.sum() <= 3 or not robust:
            break
        worst = int(np.argmax(np.where(keep, resid, -1)))
        if resid[worst] <= max(0.02, 3.0 * float(np.median(resid[keep]))):
            break
        keep[worst] = False
    resid = resid[keep]
    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    z = R.T @ vp
    if z[2] < 0:
        z = -z  # plumb direction -> zenith (the model's z is roughly up)
    return ZenithResult(z / np.linalg.norm(z), vp, int(keep.sum()), float(np.sqrt(np.mean(resid**2))))


def detect_plumb_lines(
    img: np.ndarray, cam: CameraCal, *, min_length_frac: float = 0.15, max_width_px: int = 12
) -> list[np.ndarray]:
    """Automatic detection of thin dark straight strings (plumb lines) in the undistorted image.

    Hough transform on a black-hat image finds candidates; each candidate is then refined
    on the undistorted grey image: every 2 px along it, the centroid of the dip below the
    local background across the string, skipping samples where the background differs on
    the two sides (a marker edge nearby), then a robust straight-line fit.
    Returns, per line, sub-pixel points in UNDISTORTED pixel coordinates (same K).
    """
    und = cv2.undistort(img, cam.K, cam.dist_array).astype(np.float32)
    valid = cv2.undistort(np.full_like(img, 255), cam.K, cam.dist_array) > 0
    valid = cv2.erode(valid.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    k = cv2.getStructuringElement(cv2.MORPH_RECT, (max_width_px + 3, max_width_px + 3))
    bh = cv2.morphologyEx(und, cv2.MORPH_BLACKHAT, k)
    bh[~valid] = 0
    closed = bh + und  # local background brightness
    bw = ((bh > 6.0) & (bh > 0.35 * closed)).astype(np.uint8) * 255
    H, W = img.shape
    segs = cv2.HoughLinesP(
        bw,
        1,
        np.pi / 720,
        threshold=int(min_length_frac * H * 0.5),
        minLineLength=int(min_length_frac * H),
        maxLineGap=20,
    )
    if segs is None:
        return []
    segs = segs.reshape(-1, 4).astype(float)
    # union-find grouping of collinear segments
    n = len(segs)
    parent = list(range(n))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    ang = np.arctan2(segs[:, 3] - segs[:, 1], segs[:, 2] - segs[:, 0]) % np.pi
    mid = (segs[:, :2] + segs[:, 2:]) / 2
    for i in range(n):
        ni = np.array([-np.sin(ang[i]), np.cos(ang[i])])
        for j in range(i + 1, n):
            da = abs(((ang[i] - ang[j]) + np.pi / 2) % np.pi - np.pi / 2)
            if da < np.radians(2.0) and abs((mid[j] - mid[i]) @ ni) < 8:
                parent[find(j)] = find(i)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    half = max_width_px
    offs = np.arange(-2 * half, 2 * half + 0.01, 0.5)
    inner = np.abs(offs) <= half * 0.75
    outer_l = offs < -half
    outer_r = offs > half
    lines = []
    for idx in groups.values():
        pts = np.vstack([segs[idx, :2], segs[idx, 2:]])
        c = pts.mean(0)
        _, _, vt = np.linalg.svd(pts - c)
        d = vt[0]
        nrm = np.array([-d[1], d[0]])
        t = (pts - c) @ d
        refined = []
        for step in np.arange(t.min(), t.max(), 2.0):
            p = c + step * d
            q = p + offs[:, None] * nrm
            if q[:, 0].min() < 1 or q[:, 1].min() < 1 or q[:, 0].max() > W - 2 or q[:, 1].max() > H - 2:
                continue
            qi = np.rint(q).astype(int)
            if not valid[qi[:, 1], qi[:, 0]].all():
                continue
            prof = cv2.remap(
                und,
                q[:, 0].astype(np.float32).reshape(1, -1),
                q[:, 1].astype(np.float32).reshape(1, -1),
                cv2.INTER_LINEAR,
            ).ravel()
            bl, br = np.median(prof[outer_l]), np.median(prof[outer_r])
            if (
                abs(bl - br) > 0.15 * max(bl, br) + 4
                or np.ptp(prof[outer_l]) > 12
                or np.ptp(prof[outer_r]) > 12
            ):
                continue  # background not uniform around the string here
            dip = np.clip(0.5 * (bl + br) - prof[inner], 0, None)
            if dip.max() < 6:
                continue
            dip = np.clip(dip - 0.1 * dip.max(), 0, None)
            refined.append(p + (dip @ offs[inner] / dip.sum()) * nrm)
        if len(refined) < 20:
            continue
        pts_r = np.array(refined)
        for _ in range(5):  # robust straight-line fit: drop points off the string
            c = pts_r.mean(0)
            _, _, vt = np.linalg.svd(pts_r - c)
            res = np.abs((pts_r - c) @ vt[1])
            mad = np.median(res) * 1.4826 + 1e-3
            good = res < max(3 * mad, 0.15)
            if good.all() or good.sum() < 20:
                break
            pts_r = pts_r[good]
        lines.append(pts_r)
    return _dedupe(lines)


def _dedupe(lines: list[np.ndarray], tol_px: float = 4.0) -> list[np.ndarray]:
    """Merge detections of the same string (points within ``tol_px`` of the other's line)."""
    lines = sorted(lines, key=len, reverse=True)
    out: list[np.ndarray] = []
    for ln in lines:
        dup = False
        for o in out:
            c = o.mean(0)
            _, _, vt = np.linalg.svd(o - c)
            d = np.abs((ln - c) @ np.array([-vt[0][1], vt[0][0]]))
            if np.median(d) < tol_px:
                dup = True
                break
        if not dup:
            out.append(ln)
    return out
