"""The sky camera's rotation to ENU without a survey: from its own sun detections, and its
levelling from the horizon.

**Sun (Wahba / Kabsch).**  With the site and the frame times known, pvlib gives the sun's
ENU direction ``s_i`` for each detection ``d_i`` (camera frame).  The rotation minimising
``sum |R d_i - s_i|^2`` is Kabsch's: ``R = U diag(1, 1, det(U V^T)) V^T`` from the SVD of
``sum s_i d_i^T``.  Detections off by more than three robust sigmas (a distractor, a cloud
edge) are dropped and the fit repeated.  A day of sun vectors lies on a cone about the
celestial pole, which fixes all three angles.

**Refined with the lens.**  The rotation is then refined by least squares on the *pixel*
residuals (the detection's image centre against the ephemeris projected through the lens,
a soft-L1 loss), optionally together with the lens's focal lengths, principal point and
k1, k2 held to their checkerboard values by priors (``refine="lens"``): the sun's known path
is a second calibration target that reaches the low elevations the boards seldom cover.

**Horizon.**  Along rays from the principal point near 90 deg off axis, the sky-to-ground
step is located to a fraction of a pixel; the unit vectors of those points lie on a great
circle whose pole is the zenith (smallest eigenvector of ``sum v v^T``), with trees and
buildings dropped as outliers.  It levels the camera where the horizon is visible, and
checks (or constrains) the sun fit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.optimize import least_squares

from ..errors import InputError
from ..sun.source import Site, solar_position
from ..sun.types import azel_to_enu
from .camera import CameraCal


@dataclass
class OrientationFit:
    """Result of :func:`fit_orientation` (angles in degrees)."""

    enu_from_camera: np.ndarray
    residual_deg: float  # RMS angle between R d_i and s_i over the inliers
    residual_px: float | None  # RMS pixel residual after the refinement
    used: int
    rejected: int
    tilt_deg: float  # the optical axis's angle from the zenith
    camera: CameraCal | None = None  # the refined lens (refine="lens")
    horizon_disagreement_deg: float | None = None


#: The pixel residual of a sun the fit puts behind the camera (the lens does not image it).
BEHIND_PX = 1000.0

#: How far the horizon's zenith is trusted in the refinement (deg, one sigma): terrain a
#: few tenths of a degree high and an arc cut by the frame bias it by about a tenth (0.17
#: deg on a camera tilted 15 deg), where a day of the sun fits within a hundredth.  At 0.1
#: it pulled that rotation 0.12 deg off; at 0.5, 0.01.  It still checks the fit (``check_plausible``).
HORIZON_SIGMA_DEG = 0.5

#: What ``check_plausible`` allows by default: a sky camera stands near level, and a day of
#: the sun's own sights fits a rotation within a few hundredths of a degree.
MAX_TILT_DEG = 30.0
MAX_RESIDUAL_DEG = 0.5
MAX_HORIZON_DISAGREEMENT_DEG = 1.0

#: What makes a day of the sun fit a wrong rotation well: the sun's daily path has the same
#: shape at every site and hour, so these turn the camera instead of failing the fit.
_WRONG_SITE_OR_CLOCK = (
    "a wrong --lat sign (the sun passes on the other side at noon), a wrong --lon sign, or "
    "frames named in local time without a zone (each hour turns the fit 15 deg)"
)


def check_plausible(
    fit: OrientationFit,
    *,
    max_tilt_deg: float = MAX_TILT_DEG,
    max_residual_deg: float = MAX_RESIDUAL_DEG,
    max_horizon_deg: float = MAX_HORIZON_DISAGREEMENT_DEG,
) -> None:
    """Refuse an orientation a sky camera cannot have (:class:`InputError`, naming the
    likely mistake): no rotation fits the sun's path, the camera tilted more than
    ``max_tilt_deg`` from the zenith, or the horizon's zenith that far from the sun's."""
    dis = fit.horizon_disagreement_deg
    if dis is not None and dis > max_horizon_deg:
        raise InputError(
            f"orientation: the horizon puts the zenith {dis:.2f} deg from where the sun's path "
            f"puts it (over {max_horizon_deg:g}): {_WRONG_SITE_OR_CLOCK}; or the --horizon frame "
            "shows no clear horizon (leave it out to calibrate from the sun alone)."
        )
    if fit.residual_deg > max_residual_deg:
        raise InputError(
            f"orientation: no rotation fits the sun's path: residual {fit.residual_deg:.2f} deg "
            f"(over {max_residual_deg:g}; {fit.used} detections used, {fit.rejected} rejected). "
            "Are the frames mirrored (rows written bottom-up, or flipped left-right)? Is the lens "
            "the camera's, and are the frames' times UTC?"
        )
    if fit.tilt_deg > max_tilt_deg:
        raise InputError(
            f"orientation: the fit tilts the camera {fit.tilt_deg:.1f} deg from the zenith "
            f"(over --max-tilt {max_tilt_deg:g}). A sky camera stands near level, so this is "
            f"almost always {_WRONG_SITE_OR_CLOCK}. If the camera really is tilted, give a "
            "larger --max-tilt."
        )


def kabsch(d_cam: np.ndarray, s_enu: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Rotation ``R`` (enu_from_camera) minimising ``sum w |R d - s|^2``."""
    w = np.ones(len(d_cam)) if w is None else np.asarray(w, float)
    M = (w[:, None] * s_enu).T @ d_cam
    U, _, Vt = np.linalg.svd(M)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ S @ Vt


def _angles_deg(R: np.ndarray, d_cam: np.ndarray, s_enu: np.ndarray) -> np.ndarray:
    c = np.clip(np.sum((d_cam @ R.T) * s_enu, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(c))


def sun_vectors(site: Site, times: Sequence[float]) -> np.ndarray:
    """pvlib SPA sun directions (ENU unit vectors, apparent elevation) at POSIX ``times``."""
    sp = solar_position(site, np.asarray(times, float))
    return azel_to_enu(sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy())


def fit_orientation(
    times: Sequence[float],
    d_cam: np.ndarray,
    site: Site,
    *,
    uv: np.ndarray | None = None,
    camera: CameraCal | None = None,
    refine: str | None = "rotation",
    horizon_zenith_cam: np.ndarray | None = None,
    horizon_sigma_deg: float = HORIZON_SIGMA_DEG,
    min_used: int = 6,
) -> OrientationFit:
    """``enu_from_camera`` from sun detections ``d_cam`` (N, 3) at ``times`` (POSIX s).

    ``uv`` (N, 2) and ``camera``: the detections' pixels and the lens, for the pixel
    refinement (``refine`` = ``"rotation"``, ``"lens"`` or None).  ``horizon_zenith_cam``:
    the zenith from :func:`level_from_horizon`, used as a soft constraint (sigma
    ``horizon_sigma_deg``) in the refinement and reported against the result.
    """
    d = np.asarray(d_cam, float).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    s = sun_vectors(site, times)
    if len(d) < min_used:
        raise InputError(f"orientation: {len(d)} sun detections, need >= {min_used}")
    keep = np.ones(len(d), bool)
    R = kabsch(d, s)
    for _ in range(5):
        err = _angles_deg(R, d, s)
        mad = 1.4826 * float(np.median(np.abs(err[keep] - np.median(err[keep]))))
        new = err <= np.median(err[keep]) + max(3.0 * mad, 0.05)
        if new.sum() < min_used or np.array_equal(new, keep):
            break
        keep = new
        R = kabsch(d[keep], s[keep])
    res_px = None
    cam_out = None
    if refine and uv is not None and camera is not None:
        R, cam_out, res_px = _refine(
            R, np.asarray(uv, float)[keep], s[keep], camera, refine, horizon_zenith_cam, horizon_sigma_deg
        )
        if cam_out is not None:  # the detections' directions change with the lens
            from ..vision.fisheye.lens import FisheyeLens

            d, ok = FisheyeLens.from_camera(cam_out).rays(np.asarray(uv, float))
            d = np.where(ok[:, None], d, np.asarray(d_cam, float))
    err = _angles_deg(R, d, s)
    zen = R.T @ np.array([0.0, 0.0, 1.0])
    dis = None
    if horizon_zenith_cam is not None:
        h = np.asarray(horizon_zenith_cam, float)
        dis = math.degrees(math.acos(float(np.clip(h @ zen / np.linalg.norm(h), -1, 1))))
    return OrientationFit(
        enu_from_camera=R,
        residual_deg=float(np.sqrt(np.mean(err[keep] ** 2))),
        residual_px=res_px,
        used=int(keep.sum()),
        rejected=int((~keep).sum()),
        tilt_deg=math.degrees(math.acos(float(np.clip(zen[2], -1, 1)))),
        camera=cam_out,
        horizon_disagreement_deg=dis,
    )


def _refine(
    R0: np.ndarray,
    uv: np.ndarray,
    s_enu: np.ndarray,
    cam: CameraCal,
    mode: str,
    horizon: np.ndarray | None,
    sigma_h_deg: float,
):
    """Least squares on pixels: rotation (and the lens with priors); returns (R, cam, rms px)."""
    lens_free = mode == "lens"
    p0 = np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.dist[0], cam.dist[1]])
    prior_sigma = np.array([0.5, 0.5, 0.5, 0.5, 0.004, 0.002])
    rv0 = cv2.Rodrigues(R0.T)[0].ravel()  # camera_from_enu

    def unpack(x):
        Rc = cv2.Rodrigues(x[:3])[0]
        p = x[3:] if lens_free else p0
        K = np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]])
        D = np.array([p[4], p[5], cam.dist[2], cam.dist[3]], float).reshape(4, 1)
        return Rc, K, D, p

    def residuals(x):
        Rc, K, D, p = unpack(x)
        dc = s_enu @ Rc.T
        ok = dc[:, 2] > 1e-6
        pr, _ = cv2.fisheye.projectPoints(
            np.where(ok[:, None], dc, [0, 0, 1.0]).reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D
        )
        r = pr.reshape(-1, 2) - uv
        # A sun behind the camera has no pixel: it costs its angle past 90 deg (a zero
        # residual there had let the fit turn the whole day behind the lens, 0 px).
        behind = BEHIND_PX * (1.0 + np.arcsin(np.clip(-dc[:, 2], 0.0, 1.0)))
        r = np.where(ok[:, None], r, behind[:, None])
        out = [r.ravel()]
        if lens_free:
            out.append((p - p0) / prior_sigma)
        if horizon is not None:
            z_enu = Rc.T @ (horizon / np.linalg.norm(horizon))
            out.append(z_enu[:2] / math.radians(sigma_h_deg))
        return np.concatenate(out)

    x0 = np.concatenate([rv0, p0]) if lens_free else rv0
    sol = least_squares(residuals, x0, loss="soft_l1", f_scale=0.5, x_scale="jac")
    Rc, _, _, p = unpack(sol.x)
    r = residuals(sol.x)[: 2 * len(uv)].reshape(-1, 2)
    rms = float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
    cam_out = None
    if lens_free:
        cam_out = replace(
            cam,
            fx=float(p[0]),
            fy=float(p[1]),
            cx=float(p[2]),
            cy=float(p[3]),
            dist=(float(p[4]), float(p[5]), cam.dist[2], cam.dist[3]),
        )
    return Rc.T, cam_out, rms


# ------------------------------------------------------------------------------------------
@dataclass
class HorizonLevel:
    """Zenith from the horizon (camera frame), its residual and support (degrees)."""

    zenith_cam: np.ndarray
    residual_deg: float
    points: int
    rejected: int
    tilt_deg: float


def level_from_horizon(
    image: np.ndarray,
    camera: CameraCal,
    *,
    n_rays: int = 360,
    theta_lo_deg: float = 72.0,
    min_step: float = 12.0,
    min_points: int = 40,
) -> HorizonLevel:
    """The zenith of a camera that looks up, from the sky-to-ground step near 90 deg off axis.

    ``image``: BGR or grey uint8.  Raises :class:`InputError` when the horizon is not found
    on enough rays (an obstructed view, a night frame, a camera not looking up).
    """
    from ..vision.fisheye.lens import FisheyeLens

    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    grey = cv2.GaussianBlur(grey.astype(np.float32), (0, 0), 1.0)
    lens = FisheyeLens.from_camera(camera)
    r_lo = lens.circle_radius_px(theta_lo_deg)
    r_hi = lens.circle_radius_px(89.9) * 1.08  # ~95 deg; the lens model holds that far
    phi = np.arange(n_rays) * (2 * math.pi / n_rays)
    radii = np.arange(r_lo, r_hi, 0.5)
    ax = camera.fx / math.sqrt(camera.fx * camera.fy)
    ay = camera.fy / math.sqrt(camera.fx * camera.fy)
    mx = (camera.cx + ax * np.cos(phi)[:, None] * radii[None, :]).astype(np.float32)
    my = (camera.cy + ay * np.sin(phi)[:, None] * radii[None, :]).astype(np.float32)
    inside = (mx >= 0) & (mx <= camera.width - 1) & (my >= 0) & (my <= camera.height - 1)
    vals = cv2.remap(grey, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    vals[~inside] = np.nan
    deriv = np.diff(vals, axis=1)
    pts = []
    for k in range(n_rays):
        dk = deriv[k]
        if not np.isfinite(dk).any():
            continue
        j = int(np.nanargmin(dk))
        if not 1 <= j < len(dk) - 1 or not np.isfinite(dk[j - 1 : j + 2]).all():
            continue
        sky = np.nanmedian(vals[k, max(j - 8, 0) : j])
        ground = np.nanmedian(vals[k, j + 2 : j + 10])
        if not (sky - ground >= min_step and sky - ground >= 0.25 * sky):
            continue
        y0, y1, y2 = dk[j - 1], dk[j], dk[j + 1]
        den = y0 - 2 * y1 + y2
        off = 0.5 * (y0 - y2) / den if den != 0 else 0.0
        r = radii[j] + 0.5 * (0.5 + float(np.clip(off, -0.5, 0.5)))
        pts.append((camera.cx + ax * math.cos(phi[k]) * r, camera.cy + ay * math.sin(phi[k]) * r))
    if len(pts) < min_points:
        raise InputError(f"horizon: found on {len(pts)} of {n_rays} rays, need >= {min_points}")
    v, ok = lens.rays(np.asarray(pts))
    v = v[ok]
    keep = np.ones(len(v), bool)
    z = np.array([0.0, 0.0, 1.0])
    for _ in range(6):
        _, vecs = np.linalg.eigh(v[keep].T @ v[keep])
        z = vecs[:, 0] * (1.0 if vecs[2, 0] > 0 else -1.0)
        el = np.degrees(np.arcsin(np.clip(v @ z, -1, 1)))
        med = float(np.median(el[keep]))
        mad = 1.4826 * float(np.median(np.abs(el[keep] - med)))
        new = np.abs(el - med) <= max(3.0 * mad, 0.05)
        if new.sum() < min_points or np.array_equal(new, keep):
            break
        keep = new
    el = np.degrees(np.arcsin(np.clip(v @ z, -1, 1)))
    return HorizonLevel(
        zenith_cam=z,
        residual_deg=float(np.sqrt(np.mean(el[keep] ** 2))),
        points=int(keep.sum()),
        rejected=int((~keep).sum()),
        tilt_deg=math.degrees(math.acos(float(np.clip(z[2], -1, 1)))),
    )
