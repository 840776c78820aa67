"""Checkerboard views through the fisheye, for lens calibration (``cv2.fisheye.calibrate``).

Board frame: x along the columns, y along the rows, z into the board; the inner corner
(i, j) sits at ((i + 1) square, (j + 1) square, 0).  The pose is board -> camera,
``X_cam = R X_board + t`` (OpenCV).  Edges are box-filtered analytically per pixel (the
local derivative of the board coordinates gives the pixel's footprint), so the corners are
sub-pixel exact however strongly the fisheye bends the board.
"""

from __future__ import annotations

import numpy as np

from .lens import FisheyeLens


def _rodrigues(rvec) -> np.ndarray:
    w = np.asarray(rvec, float).ravel()
    ang = np.linalg.norm(w)
    if ang < 1e-15:
        return np.eye(3)
    k = w / ang
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(ang) * K + (1 - np.cos(ang)) * K @ K


def board_corners(pattern=(9, 6), square=0.04) -> np.ndarray:
    """Inner corners (N, 3) in the board frame, row by row (OpenCV's order)."""
    nx, ny = pattern
    j, i = np.mgrid[0:ny, 0:nx]
    return np.stack([(i.ravel() + 1) * square, (j.ravel() + 1) * square, np.zeros(nx * ny)], 1)


def render_checkerboard(
    lens: FisheyeLens,
    rvec,
    tvec,
    *,
    pattern=(9, 6),
    square=0.04,
    rng: np.random.Generator | None = None,
    noise_dn: float = 1.5,
) -> np.ndarray:
    """Grey (H, W) uint8 view of a planar checkerboard at pose board -> camera."""
    rng = rng if rng is not None else np.random.default_rng(0)
    R = _rodrigues(rvec)
    t = np.asarray(tvec, float).ravel()
    d, ok = lens.rays()
    d = d.astype(np.float64)
    n = R[:, 2]
    denom = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (n @ t) / denom
    P = d * s[..., None] - t
    X = P @ R  # R^T (p - t)
    valid = ok & np.isfinite(s) & (s > 0)
    a = np.where(valid, X[..., 0] / square, -100.0)
    b = np.where(valid, X[..., 1] / square, -100.0)
    wa = np.abs(np.gradient(a, axis=1)) + np.abs(np.gradient(a, axis=0)) + 1e-9
    wb = np.abs(np.gradient(b, axis=1)) + np.abs(np.gradient(b, axis=0)) + 1e-9

    def smooth_sign(x, w):
        f = x - np.floor(x)
        dist = np.minimum(f, 1 - f)
        sgn = np.where(np.floor(x) % 2 == 0, 1.0, -1.0)
        return sgn * np.clip(2 * dist / w, 0, 1)

    val = 0.5 + 0.5 * smooth_sign(a, wa) * smooth_sign(b, wb)
    nx, ny = pattern
    inside = (a > 0) & (a < nx + 1) & (b > 0) & (b < ny + 1)
    margin = (a > -1) & (a < nx + 2) & (b > -1) & (b < ny + 2)
    img = np.where(ok, 0.35, 0.0)
    img = np.where(margin & valid, 0.92, img)
    img = np.where(inside & valid, 0.08 + 0.84 * val, img)
    dn = img * 230 + rng.normal(0, noise_dn, img.shape)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def checkerboard_poses(
    lens: FisheyeLens,
    n: int,
    rng: np.random.Generator,
    *,
    pattern=(9, 6),
    square=0.04,
    max_theta_deg: float = 72.0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Board poses spread over the field (off-axis angles up to ``max_theta_deg``), each
    roughly facing the camera, spanning ~25-45 deg, wholly inside the image circle."""
    nx, ny = pattern
    w, h = (nx + 1) * square, (ny + 1) * square
    corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n and tries < 200 * n:
        tries += 1
        # even coverage in theta: half the boards beyond 40 deg, where the distortion lives
        theta = np.radians(
            rng.uniform(0.0, max_theta_deg) if len(poses) % 2 else rng.uniform(40.0, max_theta_deg)
        )
        phi = rng.uniform(0, 2 * np.pi)
        c_dir = np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        span = np.radians(rng.uniform(25.0, 45.0))
        dist = max(w, h) / span
        # board z (into the board) along the viewing ray, tilted by up to 30 deg
        z = c_dir + rng.normal(0, 0.25, 3)
        z /= np.linalg.norm(z)
        if z @ c_dir < np.cos(np.radians(35)):
            continue
        x = np.cross([0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0], z)
        x /= np.linalg.norm(x)
        roll = rng.uniform(0, 2 * np.pi)
        y0 = np.cross(z, x)
        x, y = np.cos(roll) * x + np.sin(roll) * y0, -np.sin(roll) * x + np.cos(roll) * y0
        R = np.stack([x, y, z], axis=1)  # columns: board axes in the camera frame
        t = c_dir * dist - R @ np.array([w / 2, h / 2, 0.0])
        pc = corners @ R.T + t
        if np.any(pc @ c_dir < 0.05):
            continue
        uv, inside = lens.project(pc / np.linalg.norm(pc, axis=1, keepdims=True))
        th = np.degrees(np.arctan2(np.hypot(pc[:, 0], pc[:, 1]), pc[:, 2]))
        if not inside.all() or th.max() > max_theta_deg + 8:
            continue
        if (
            uv[:, 0].min() < 8
            or uv[:, 1].min() < 8
            or uv[:, 0].max() > lens.width - 9
            or uv[:, 1].max() > lens.height - 9
        ):
            continue
        rvec = _rvec(R)
        poses.append((rvec, t))
    return poses


def _rvec(R: np.ndarray) -> np.ndarray:
    c = np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)
    ang = np.arccos(c)
    if ang < 1e-12:
        return np.zeros(3)
    if np.pi - ang < 1e-6:
        k = np.sqrt(np.maximum((np.diag(R) + 1) / 2, 0))
        k[1] = np.copysign(k[1], R[0, 1])
        k[2] = np.copysign(k[2], R[0, 2])
        return k * ang
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2 * np.sin(ang))
    return v * ang
