"""The glare's candidates: connected blobs of near-saturated pixels and their inscribed disks.

Pixels within a few grey levels of the frame's peak form connected blobs.  Each blob's
centres are the maxima of its distance transform (the centres of its largest inscribed
disks), which a thin smear column or a cloud edge joined to the glare barely moves; a
disk's radius is also read after a 3 x 3 average, so that noise added after the clip, which
riddles the plateau, does not shrink it.  The disks are where :func:`.glare.fit_glare`
starts its rays (docs/fisheye.md, step 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class Blob:
    """A connected region of (near-)saturated pixels and its inscribed-disk centres."""

    area_px: int
    bbox: tuple[int, int, int, int]  # x, y, w, h
    centres: list[tuple[float, float, float]]  # (x, y, inscribed radius px)


def find_blobs(
    grey: np.ndarray,
    threshold: float,
    valid: np.ndarray | None,
    *,
    max_blobs: int = 6,
    min_area_px: int = 3,
    mask_out: np.ndarray | None = None,
) -> list[Blob]:
    """Blobs of ``grey >= threshold`` inside ``valid``, largest first.

    The blobs are labelled on a block-reduced mask (any saturated pixel marks its block),
    then measured at full resolution inside their boxes: a coarse search, then small ROIs.
    ``mask_out``: a uint8 array of ``grey``'s shape to hold the mask (see
    :class:`.channel.FrameBuffers`); without it, a fresh one.
    """
    _, binary = cv2.threshold(grey, threshold - 0.5, 255, cv2.THRESH_BINARY, dst=mask_out)
    if valid is not None:
        binary &= valid
    H, W = binary.shape
    f = max(1, min(H, W) // 120)
    if H % f == 0 and W % f == 0:
        # a block is marked by its largest value: a dilation read at the blocks' corners
        # (50 us at 640 x 480 against INTER_AREA's 140; the same marks)
        small = np.ascontiguousarray(cv2.dilate(binary, np.ones((f, f), np.uint8), anchor=(0, 0))[::f, ::f])
    else:  # blocks of a fractional size: the marked pixels' share of each, over nothing
        small = cv2.resize(binary, (max(W // f, 1), max(H // f, 1)), interpolation=cv2.INTER_AREA)
        small = (small > 0).astype(np.uint8)
    # 16-bit labels where they cannot overflow (at most a quarter of the pixels are separate
    # 8-connected blobs): the same labels, 40-95 us against 32-bit ones' 130 at 160 x 120
    ltype = cv2.CV_16U if small.size <= 4 * 65535 else cv2.CV_32S
    n, _, stats, _ = cv2.connectedComponentsWithStats(small, connectivity=8, ltype=ltype)
    if n <= 1:
        return []
    sx, sy = W / small.shape[1], H / small.shape[0]
    out = []
    for lab in range(1, n):
        x, y, w, h = (int(v) for v in stats[lab, :4])
        x0, y0 = max(int(x * sx) - 2, 0), max(int(y * sy) - 2, 0)
        x1, y1 = min(math.ceil((x + w) * sx) + 2, W), min(math.ceil((y + h) * sy) + 2, H)
        sub = binary[y0:y1, x0:x1]
        area = int(cv2.countNonZero(sub))
        if area < min_area_px:
            continue
        dt = _inscribed_dt(sub > 0)
        dt_avg = _averaged_core_dt(grey, valid, (x0, y0, x1, y1), threshold)
        centres = [
            (x, y, max(r, float(dt_avg[int(y) - y0, int(x) - x0]))) for x, y, r in _dt_centres(dt, x0, y0)
        ]
        out.append(Blob(area, (x0, y0, x1 - x0, y1 - y0), centres))
    out.sort(key=lambda b: -b.area_px)
    return out[:max_blobs]


def _averaged_core_dt(
    grey: np.ndarray, valid: np.ndarray | None, box: tuple[int, int, int, int], threshold: float
) -> np.ndarray:
    """Distance transform of the box's near-saturated core after a 3 x 3 average (threshold
    lowered by what the average took off the box's peak).  Noise added after the clip (by a
    camera's pipeline or a renderer) takes pixels of a saturated plateau under the
    threshold; the holes leave the blob's inscribed disk, the rays' first radius, well
    inside the glare, and the rays end before its rim.  A clean plateau is the same either
    way, so the larger of the two radii is kept."""
    x0, y0, x1, y1 = box
    H, W = grey.shape
    wx0, wy0, wx1, wy1 = max(x0 - 1, 0), max(y0 - 1, 0), min(x1 + 1, W), min(y1 + 1, H)
    win = grey[wy0:wy1, wx0:wx1]
    avg = cv2.blur(win, (3, 3))[y0 - wy0 : y1 - wy0, x0 - wx0 : x1 - wx0]
    core = avg >= threshold - 0.5 - (float(win.max()) - float(avg.max()))
    if valid is not None:
        core &= valid[y0:y1, x0:x1] > 0
    return _inscribed_dt(core)


def _inscribed_dt(mask: np.ndarray) -> np.ndarray:
    """Distance transform (px) of a boolean mask, the box's edge counting as background
    when nothing inside it does: a flat or white frame is one blob with no background, whose
    transform is otherwise unbounded (a kernel that size raised)."""
    if mask.all():
        padded = cv2.copyMakeBorder(mask.astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
        return np.asarray(cv2.distanceTransform(padded, cv2.DIST_L2, 5))[1:-1, 1:-1]
    return np.asarray(cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, 5))


def _dt_centres(dt: np.ndarray, x0: int, y0: int, k: int = 3) -> list[tuple[float, float, float]]:
    """Up to ``k`` well-separated maxima of a distance transform: (x, y, radius) px."""
    top = float(dt.max())
    if top <= 0:
        return []
    size = max(3, int(2 * top) | 1)
    peaks = (dt >= cv2.dilate(dt, np.ones((size, size), np.uint8))) & (dt >= max(1.0, 0.5 * top))
    ys, xs = np.nonzero(peaks)
    vals = dt[ys, xs]
    order = np.argsort(-vals)
    chosen: list[tuple[float, float, float]] = []
    for i in order:
        x, y, r = float(xs[i] + x0), float(ys[i] + y0), float(vals[i])
        if all(math.hypot(x - cx, y - cy) > max(r, cr) for cx, cy, cr in chosen):
            chosen.append((x, y, r))
        if len(chosen) >= k:
            break
    return chosen


def core_fill(grey: np.ndarray, c: tuple[float, float], r: float, level: float) -> float:
    """Fraction of the pixels within 0.7 r of the centre that are at or above ``level``."""
    rr = max(0.7 * r, 1.0)
    x0, x1 = max(int(c[0] - rr), 0), min(int(c[0] + rr) + 2, grey.shape[1])
    y0, y1 = max(int(c[1] - rr), 0), min(int(c[1] + rr) + 2, grey.shape[0])
    if x1 <= x0 or y1 <= y0:
        return 0.0
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - c[0]) ** 2 + (yy - c[1]) ** 2 <= rr * rr
    if not inside.any():
        return 0.0
    return float(np.mean(grey[y0:y1, x0:x1][inside] >= level))
