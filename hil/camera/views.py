"""Calibration views: checkerboards for the intrinsics, plumb lines for levelling, and the
marker view for the pose (each rendered through the same camera model and sensor)."""

from __future__ import annotations

import cv2
import numpy as np

from .camera import CameraModel
from .globe import globe_bbox
from .render import Frame, expose, radiance_image, render_frame
from .scene import Scenario


def render_checkerboard(
    cam: CameraModel,
    rvec,
    tvec,
    *,
    pattern=(9, 6),
    square=0.04,
    rng: np.random.Generator | None = None,
    noise_dn: float = 1.5,
) -> np.ndarray:
    """A planar checkerboard (``pattern`` inner corners, ``square`` m) at pose board->camera.

    Board frame: x along the columns, y along the rows, z into the board; inner corner
    (i, j) sits at ((i+1) square, (j+1) square, 0).  Edges are box-filtered analytically
    per pixel so the corners are sub-pixel exact.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    Rb = cv2.Rodrigues(np.asarray(rvec, float))[0]
    tb = np.asarray(tvec, float).ravel()
    d = cam.ray_dirs()
    nb = Rb[:, 2]
    denom = d @ nb
    with np.errstate(divide="ignore", invalid="ignore"):
        tt = (nb @ tb) / denom
    P = d * tt[..., None] - tb
    X = P @ Rb  # board coords = R^T (p - t)
    a = X[..., 0] / square
    b = X[..., 1] / square
    valid = np.isfinite(tt) & (tt > 0)
    a = np.where(valid, a, -100)
    b = np.where(valid, b, -100)
    wa = np.abs(np.gradient(a, axis=1)) + np.abs(np.gradient(a, axis=0)) + 1e-9
    wb = np.abs(np.gradient(b, axis=1)) + np.abs(np.gradient(b, axis=0)) + 1e-9

    def smooth_sign(x, w):
        f = x - np.floor(x)
        dist = np.minimum(f, 1 - f)  # to nearest integer edge
        sgn = np.where(np.floor(x) % 2 == 0, 1.0, -1.0)
        return sgn * np.clip(2 * dist / w, 0, 1)

    val = 0.5 + 0.5 * smooth_sign(a, wa) * smooth_sign(b, wb)
    nx, ny = pattern
    inside = (a > 0) & (a < nx + 1) & (b > 0) & (b < ny + 1)
    margin = (a > -1) & (a < nx + 2) & (b > -1) & (b < ny + 2)
    img = np.full(a.shape, 0.35)
    img = np.where(margin & valid, 0.92, img)
    img = np.where(inside & valid, 0.08 + 0.84 * val, img)
    dn = img * 230 + rng.normal(0, noise_dn, img.shape)
    return np.clip(np.rint(dn), 0, 255).astype(np.uint8)


def checkerboard_poses(
    cam: CameraModel, n: int, rng: np.random.Generator, *, pattern=(9, 6), square=0.04
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Varied board poses that keep the whole board in view (for intrinsics)."""
    nx, ny = pattern
    w, h = (nx + 1) * square, (ny + 1) * square
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    tries = 0
    while len(poses) < n and tries < 50 * n:
        tries += 1
        # distance so that the board covers ~40-70 % of the smaller image side
        frac = rng.uniform(0.45, 0.8)
        dist = max(cam.fx, cam.fy) * max(w, h) / (frac * min(cam.width, cam.height) * 1.2)
        ang = np.radians(rng.uniform(-35, 35, 3)) * np.array([1, 1, 0.5])
        Rb = cv2.Rodrigues(ang)[0]
        # aim the board centre at a random image point
        u = rng.uniform(0.2, 0.8) * cam.width
        v = rng.uniform(0.2, 0.8) * cam.height
        ray = cam.rays_at([[u, v]])[0]
        centre = ray * dist / ray[2]
        tb = centre - Rb @ np.array([w / 2, h / 2, 0.0])
        corners = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], float)
        pc = corners @ Rb.T + tb
        if np.any(pc[:, 2] < 0.05):
            continue
        uv = cam.project(corners, cv2.Rodrigues(Rb)[0], tb)
        if uv.min() < 10 or np.any(uv[:, 0] > cam.width - 10) or np.any(uv[:, 1] > cam.height - 10):
            continue
        poses.append((cv2.Rodrigues(Rb)[0].ravel(), tb))
    return poses


def plumb_lines(scn: Scenario, n_lines: int = 4) -> list[tuple[np.ndarray, np.ndarray]]:
    """Plumb strings (model frame): (top point, bottom point), hung between camera and globe,
    beside the globe, truly vertical (along the ENU zenith)."""
    cam = scn.camera
    pose = scn.pose
    zen = scn.zenith_model
    C = pose.center
    D = np.linalg.norm(C)
    out = []
    r0, r1, c0, c1 = globe_bbox(scn, pose)
    W = cam.width
    k = max(n_lines // 2, 1)
    left = np.linspace(0.08 * W, max(c0 - 0.05 * W, 0.1 * W), k)
    right = np.linspace(min(c1 + 0.05 * W, 0.9 * W), 0.92 * W, n_lines - k)
    xs = np.concatenate([left, right]) / W
    vrow = min(0.5 * (r0 + r1) / cam.height + 0.1, 0.8)
    for fx_ in xs:
        ray_cam = cam.rays_at([[fx_ * cam.width, vrow * cam.height]])[0]
        ray = np.asarray(pose.R).T @ ray_cam
        P = C + ray * 0.75 * D
        top = P + zen * 0.35
        bot = P - zen * 0.35
        if bot @ zen < 0.005:  # keep above the base
            bot = P - zen * ((P @ zen) - 0.005)
        out.append((top, bot))
    return out


def render_plumb_view(
    scn: Scenario,
    t: float,
    *,
    n_lines: int = 4,
    string_diameter=0.003,
    rng: np.random.Generator | None = None,
) -> Frame:
    """The installed camera's view with plumb strings hung in it (for levelling)."""
    rng = rng if rng is not None else np.random.default_rng(1)
    pose = scn.pose
    sun = scn.sun([t])
    s_model = sun["model"][0]
    L = radiance_image(scn, pose, s_model, float(sun["dni"][0]), float(sun["dhi"][0]))
    cam = scn.camera
    d = cam.ray_dirs().reshape(-1, 3) @ np.asarray(pose.R)
    C = pose.center
    f = np.sqrt(cam.fx * cam.fy)
    lines = plumb_lines(scn, n_lines)
    Lf = L.reshape(-1)
    L_string = 0.04 / np.pi * (float(sun["dhi"][0]) + 0.3 * float(sun["dni"][0]))
    truth_lines = []
    for top, bot in lines:
        z = (top - bot) / np.linalg.norm(top - bot)
        w = C - bot
        # closest points between ray C + t d and line bot + s z
        dz = d @ z
        denom = 1 - dz**2
        dw = d @ w
        zw = z @ w
        tr = (dz * zw - dw) / np.maximum(denom, 1e-12)
        sl = (zw - dz * dw) / np.maximum(denom, 1e-12)
        seg = np.linalg.norm(top - bot)
        cl = C + tr[:, None] * d - (bot + np.clip(sl, 0, seg)[:, None] * z)
        dist_px = np.linalg.norm(cl, axis=1) / np.maximum(tr, 1e-6) * f
        rad_px = string_diameter / 2 / np.maximum(tr, 1e-6) * f
        cov = np.clip(rad_px - dist_px + 0.5, 0, 1) * (tr > 0)
        Lf = Lf * (1 - cov) + L_string * cov
        samples = bot + np.linspace(0, seg, 50)[:, None] * z
        truth_lines.append(cam.project(samples, pose.rvec, pose.tvec))
    img = expose(Lf.reshape(L.shape).astype(np.float32), scn, rng, exposure_factor=2.0)
    return Frame(img, {"lines_uv": truth_lines, "zenith_model": scn.zenith_model, "lines_model": lines})


def render_marker_view(scn: Scenario, t: float, rng: np.random.Generator | None = None) -> Frame:
    """The installed camera's view used for exterior orientation (longer exposure)."""
    return render_frame(scn, t, rng=rng, pose=scn.pose, exposure_factor=2.0)
