"""The paper's pipeline (paper 003, Zheng & Xue 2015), literally, as ``--algorithm seed``.

1. RGB -> HSI with the standard formulas: ``I = (R + G + B) / 3``,
   ``S = 1 - 3 min(R, G, B) / (R + G + B)``, ``H = theta`` if ``B <= G`` else
   ``360 - theta``, ``theta = arccos(((R-G) + (R-B)) / 2 / sqrt((R-G)^2 + (R-B)(G-B)))``.
2. Weighted HSI ``F' = {K_H H, K_S S, K_I I}`` with ``K_H = 0.15, K_S = 0.30, K_I = 0.65``.
   The paper's segmentation equation (its Eq. 5) is lost in the text; our reading: a pixel
   is a high-brightness pixel when its weighted HSI vector is within ``delta`` of the sun's,
   white at full intensity ``{K_H 0, K_S 0, K_I 1}`` (hue as a fraction of the circle,
   measured on the circle; an achromatic pixel's hue is 0).
3. Fisheye -> plane by the spherical, longitude-coordinate correction (its Eqs. 6-7, also
   lost; the standard form of its references [14-15]): the lens is a hemisphere of 180 deg,
   centre ``(x0, y0)``, radius ``R``; the row is kept, ``y = V``, and the column is
   stretched back to its longitude, ``x - x0 = (U - x0) R / sqrt(R^2 - (V - y0)^2)``.
   Applied to the segmented mask (nearest neighbour), as the paper orders its steps.
4. Rules on each 8-connected spot of the corrected mask, all three must hold:
   ``Omega = W/L in (0.8, 1.2)`` (bounding box), ``Phi = N/N_T in (0.5, 1.2)`` with
   ``N_T = 400`` px at 640 x 480 (scaled with the pixel count), and the centroid within a
   bound of the previous one in the sequence.  The paper gives no number and compares
   consecutive samples of a tracking camera; here the bound is 20 px (at 640 px width,
   scaled) plus the sun's largest motion since the previous sample (0.3 deg/min at the
   image centre's scale), so frames minutes apart are judged alike.  Several passing spots:
   the largest.
5. Centroid ``(U, V)``; offsets ``dh = U - W/2`` (altitude), ``da = V - H/2`` (azimuth).

Direction (for the sky-fixed benchmark; the paper only uses the offsets): the corrected
coordinates are longitude and latitude on the hemisphere, ``sin(lambda) = (U - x0) / R``,
``sin(beta) = (V - y0) / R``, i.e. ``d_cam = (cos b sin l, sin b, cos b cos l)``; ``x0, y0``
are the bundle's principal point and ``R`` the radius of its 90-deg circle.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ...calibration.fisheye_bundle import FisheyeBundle
from ...sun.types import enu_to_azel
from .lens import FisheyeLens
from .pipeline import FramePipeline
from .result import FisheyeResult, not_found

K_H, K_S, K_I = 0.15, 0.30, 0.65
N_T_640x480 = 400.0
ASPECT = (0.8, 1.2)
AREA = (0.5, 1.2)


def weighted_hsi(bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_H H, K_S S, K_I I) with H in [0, 1) (fraction of 360 deg), S and I in [0, 1]."""
    f = bgr.astype(np.float32) / 255.0
    B, G, R = f[:, :, 0], f[:, :, 1], f[:, :, 2]
    total = R + G + B
    intensity = total / 3.0
    with np.errstate(divide="ignore", invalid="ignore"):
        sat = np.where(total > 0, 1.0 - 3.0 * np.minimum(np.minimum(R, G), B) / total, 0.0)
        num = 0.5 * ((R - G) + (R - B))
        den = np.sqrt((R - G) ** 2 + (R - B) * (G - B))
        theta = np.arccos(np.clip(np.where(den > 1e-9, num / den, 1.0), -1.0, 1.0))
    hue = np.where(B <= G, theta, 2 * np.pi - theta) / (2 * np.pi)
    hue = np.where(den > 1e-9, hue, 0.0) % 1.0
    return K_H * hue, K_S * sat, K_I * intensity


def segment(bgr: np.ndarray, delta: float) -> np.ndarray:
    """High-brightness mask (uint8 0/255): weighted HSI within ``delta`` of the sun's white."""
    h, s, i = weighted_hsi(bgr)
    dh = np.minimum(h, K_H - h)  # hue distance to 0 on the circle (weighted)
    dist = np.sqrt(dh * dh + s * s + (K_I - i) ** 2)
    return np.where(dist <= delta, 255, 0).astype(np.uint8)


class SeedEstimator(FramePipeline):
    """The paper's pipeline for one camera; remembers the previous sun centroid of the
    sequence (rule 3).  Same interface and result as the default pipeline."""

    algorithm = "seed"

    def __init__(
        self,
        bundle: FisheyeBundle,
        *,
        delta: float = 0.10,
        n_t: float | None = None,
        offset_bound_px: float | None = None,
    ):
        cam = bundle.camera
        self.bundle = bundle
        self.shape = (cam.height, cam.width)
        scale = cam.width * cam.height / (640.0 * 480.0)
        self.n_t = float(n_t) if n_t is not None else N_T_640x480 * scale
        self.offset_bound = (
            float(offset_bound_px) if offset_bound_px is not None else 20.0 * cam.width / 640.0
        )
        self.delta = delta
        self.R = bundle.enu_from_camera
        self.frame = "enu" if self.R is not None else "model"
        lens = FisheyeLens.from_camera(cam)
        self.x0, self.y0 = cam.cx, cam.cy
        self.radius = lens.circle_radius_px(89.9)
        self._maps = self._longitude_maps()
        self._prev: tuple[float, float, float | None] | None = None
        self._deg_per_px = lens.deg_per_px(cam.cx, cam.cy)

    def reset_sequence(self) -> None:
        self._prev = None

    def _longitude_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """Inverse maps of the correction: for each corrected pixel (X, Y), the fisheye pixel
        ``x = x0 + (X - x0) sqrt(R^2 - (Y - y0)^2) / R``, ``y = Y``."""
        H, W = self.shape
        Y, X = np.mgrid[0:H, 0:W].astype(np.float32)
        half = np.sqrt(np.maximum(self.radius**2 - (Y - self.y0) ** 2, 0.0))
        mx = (self.x0 + (X - self.x0) * half / self.radius).astype(np.float32)
        inside = (np.abs(X - self.x0) <= self.radius) & (half > 0)
        mx[~inside] = -1.0
        return mx, Y

    def correct(self, mask: np.ndarray) -> np.ndarray:
        """The longitude correction of a mask (nearest neighbour)."""
        return cv2.remap(
            mask,
            self._maps[0],
            self._maps[1],
            cv2.INTER_NEAREST,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )

    def estimate_image(self, image, t: float | None = None, prior=None) -> FisheyeResult:
        """The paper's steps on one frame (``prior`` is accepted and ignored)."""
        img, refused = self.checked_frame(image, t)
        if img is None:
            assert refused is not None
            return refused
        corrected = self.correct(segment(img, self.delta))
        n, _, stats, cents = cv2.connectedComponentsWithStats(corrected, connectivity=8)
        if n <= 1:
            return not_found(None, "no_bright_region", t, self.frame, self.algorithm)
        passing, failed = [], {"shape": 0, "area": 0, "offset": 0}
        bound = self.offset_bound
        if self._prev is not None and self._prev[2] is not None and t is not None:
            bound += 0.3 * abs(t - self._prev[2]) / 60.0 / self._deg_per_px
        for k in range(1, n):
            w, h, area = (
                float(stats[k, i]) for i in (cv2.CC_STAT_WIDTH, cv2.CC_STAT_HEIGHT, cv2.CC_STAT_AREA)
            )
            u, v = float(cents[k, 0]), float(cents[k, 1])
            if not ASPECT[0] < w / h < ASPECT[1]:
                failed["shape"] += 1
            elif not AREA[0] < area / self.n_t < AREA[1]:
                failed["area"] += 1
            elif self._prev is not None and math.hypot(u - self._prev[0], v - self._prev[1]) > bound:
                failed["offset"] += 1
            else:
                passing.append((area, u, v))
        if not passing:
            return not_found(
                None, "no_region_passes_rules", t, self.frame, self.algorithm, rejected=failed, regions=n - 1
            )
        area_px, U, V = max(passing)
        self._prev = (U, V, t)
        lam = math.asin(float(np.clip((U - self.x0) / self.radius, -1, 1)))
        beta = math.asin(float(np.clip((V - self.y0) / self.radius, -1, 1)))
        d_cam = np.array([math.cos(beta) * math.sin(lam), math.sin(beta), math.cos(beta) * math.cos(lam)])
        vec = self.R @ d_cam if self.R is not None else d_cam
        az, el = enu_to_azel(vec)
        H, W = self.shape
        # the centroid back in the fisheye image (the row is kept by the correction)
        half = math.sqrt(max(self.radius**2 - (V - self.y0) ** 2, 0.0))
        u_fish = self.x0 + (U - self.x0) * half / self.radius
        flags = ("several_candidates",) if len(passing) > 1 else ()
        return FisheyeResult(
            image=None,
            found=True,
            time=t,
            frame=self.frame,
            algorithm=self.algorithm,
            az_deg=float(az),
            el_deg=float(el),
            sigma_deg=1.0,
            d_cam=d_cam,
            centre_uv=(u_fish, V),
            offset_px=(U - W / 2, V - H / 2),
            offset_deg=(
                math.degrees(math.atan2(d_cam[0], d_cam[2])),
                math.degrees(math.atan2(d_cam[1], d_cam[2])),
            ),
            quality=flags,
            extra={"area_px": int(area_px), "corrected_uv": [round(U, 3), round(V, 3)]},
        )
