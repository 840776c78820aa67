"""Hotspot (glint) segmentation: the paper's Algorithm 1, literally, and a fast equivalent.

Algorithm 1 (paper 000):
1. I_min, I_max = min/max grey inside the surface mask M.
2. No glint unless I_max is in the top 10 % of the radiometric range (>= 230 for 8 bit).
3. For i = I_max, I_max - 1, ..., down to the end threshold: label the connected components
   of M AND (I > i); the candidate is the component with the largest mean brightness;
   record (i, A_i) with A_i its area.  End threshold: the pseudo-code's (I_max - I_min)/2
   (default) or the prose's (I_max + I_min)/2 (``end_rule="prose"``).
4. i_opt = the threshold whose (i, A_i) lies farthest from the straight line through the
   first and last pairs (paper eqs. 3-4).
5. H = M AND (I > i_opt), keep the component of largest mean brightness, morphological
   closing.

Both implementations use 8-connectivity, and break ties of equal mean brightness by the
larger area, then the earlier first pixel in raster order, so they are deterministic and
return identical masks.  ``segment_fast`` only looks at the bounding box of
M AND (I > last threshold), padded by twice the closing radius: every component of every
threshold lies inside it, so labels, means, areas and the closing are the same as on the
full frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

CLOSING_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
_CLOSE_R = 2


@dataclass
class Segmentation:
    """Result of hotspot segmentation.  ``mask`` is the full-frame uint8 H (0/1) or None."""

    found: bool
    reason: str | None
    mask: np.ndarray | None = None
    roi: tuple[int, int, int, int] | None = None  # r0, r1, c0, c1 of the work window
    i_opt: int | None = None
    i_max: int = 0
    i_min: int = 0
    n_candidates: int = 0  # components of M AND (I > i_opt)
    area: int = 0
    curve: list[tuple[int, int]] | None = None  # (i, A_i)
    roi_mask: np.ndarray | None = None  # H restricted to ``roi``


def _end_threshold(imax: int, imin: int, end_rule: str) -> int:
    end = (imax - imin) / 2 if end_rule == "pseudocode" else (imax + imin) / 2
    return int(math.ceil(end))


def _candidate(
    labels: np.ndarray, n: int, stats: np.ndarray, img: np.ndarray, offset: tuple[int, int], full_width: int
) -> int:
    """Label of the component with the largest mean brightness (ties: area, raster order)."""
    if n <= 1:
        return 0
    sums = np.bincount(labels.ravel(), weights=img.ravel(), minlength=n)[1:]
    areas = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    means = sums / areas
    best = np.flatnonzero(means == means.max())
    if best.size > 1:
        a = areas[best]
        best = best[a == a.max()]
    if best.size > 1:
        # the tied component whose first pixel comes first in raster order (one pass)
        flat = labels.ravel()
        first = np.full(n, flat.size, np.int64)
        np.minimum.at(first, flat, np.arange(flat.size))
        h, w = labels.shape
        rows, cols = np.divmod(first[best + 1], w)
        raster = (rows + offset[0]) * full_width + (cols + offset[1])
        best = best[[int(np.argmin(raster))]]
    return int(best[0]) + 1


def _sweep(img: np.ndarray, m: np.ndarray, imax: int, i_end: int, offset, full_width):
    curve = []
    for i in range(imax, i_end - 1, -1):
        b = ((img > i) & m).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(b, connectivity=8)
        k = _candidate(labels, n, stats, img, offset, full_width)
        curve.append((i, int(stats[k, cv2.CC_STAT_AREA]) if k else 0))
    return curve


def _knee(curve: list[tuple[int, int]]) -> int:
    """Threshold of the pair farthest from the line through the first and last pairs."""
    (i0, a0), (i1, a1) = curve[0], curve[-1]
    di, da = i1 - i0, a1 - a0
    norm = math.hypot(di, da)
    if norm == 0:
        return curve[0][0]
    best, best_d = curve[0][0], -1.0
    for i, a in curve:
        d = abs(da * (i - i0) - di * (a - a0)) / norm
        if d > best_d:
            best, best_d = i, d
    return best


def _final(img, m, i_opt, offset, full_width):
    b = ((img > i_opt) & m).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(b, connectivity=8)
    k = _candidate(labels, n, stats, img, offset, full_width)
    h = (labels == k).astype(np.uint8) if k else np.zeros_like(b)
    h = cv2.morphologyEx(h, cv2.MORPH_CLOSE, CLOSING_KERNEL)
    return h, n - 1


def _minmax(image, mask):
    imin, imax, _, _ = cv2.minMaxLoc(image, mask=mask)
    return int(imin), int(imax)


def segment_seed(
    image: np.ndarray, mask: np.ndarray, *, end_rule: str = "pseudocode", glint_level: int = 230
) -> Segmentation:
    """The paper's Algorithm 1, literally, on the whole frame (slow: one labelling of the full
    frame per threshold)."""
    img = np.ascontiguousarray(image)
    m = mask > 0
    if not m.any():
        return Segmentation(False, "empty_mask")
    imin, imax = _minmax(img, m.astype(np.uint8))
    if imax < glint_level:
        return Segmentation(False, "no_glint", i_max=imax, i_min=imin)
    i_end = _end_threshold(imax, imin, end_rule)
    W = img.shape[1]
    curve = _sweep(img, m, imax, i_end, (0, 0), W)
    i_opt = _knee(curve)
    h, ncand = _final(img, m, i_opt, (0, 0), W)
    return Segmentation(
        True,
        None,
        mask=h,
        roi=(0, img.shape[0], 0, img.shape[1]),
        i_opt=i_opt,
        i_max=imax,
        i_min=imin,
        n_candidates=ncand,
        area=int(h.sum()),
        curve=curve,
        roi_mask=h,
    )


#: More separate saturated spots than this is not one glint (hot pixels, noise, a lit
#: surface): :func:`segment_fast` gives up before the threshold sweep.
MAX_SATURATED_SPOTS = 8


def segment_fast(
    image: np.ndarray,
    mask: np.ndarray,
    *,
    end_rule: str = "pseudocode",
    glint_level: int = 230,
    full_mask: bool = True,
) -> Segmentation:
    """Same H as :func:`segment_seed`, computed on the window that can hold it.

    A frame with more than :data:`MAX_SATURATED_SPOTS` separate spots above
    ``glint_level`` is refused at once (``ambiguous_bright_spots``): the sweep would have to
    label the whole frame at every threshold to find no glint in it.
    """
    img = np.ascontiguousarray(image)
    m8 = mask if mask.dtype == np.uint8 else (mask > 0).astype(np.uint8)
    imin, imax = _minmax(img, m8)
    if imax == 0 and not m8.any():
        return Segmentation(False, "empty_mask")
    if imax < glint_level:
        return Segmentation(False, "no_glint", i_max=imax, i_min=imin)
    _, hi = cv2.threshold(img, glint_level - 1, 1, cv2.THRESH_BINARY)
    spots = cv2.connectedComponents(cv2.bitwise_and(hi, m8), connectivity=8)[0] - 1
    if spots > MAX_SATURATED_SPOTS:
        return Segmentation(False, "ambiguous_bright_spots", i_max=imax, i_min=imin, n_candidates=spots)
    i_end = _end_threshold(imax, imin, end_rule)
    _, b = cv2.threshold(img, i_end, 1, cv2.THRESH_BINARY)
    b = cv2.bitwise_and(b, m8)
    x, y, w, h = cv2.boundingRect(b)
    pad = 2 * _CLOSE_R + 1
    H, W = img.shape
    r0, r1 = max(y - pad, 0), min(y + h + pad, H)
    c0, c1 = max(x - pad, 0), min(x + w + pad, W)
    sub = img[r0:r1, c0:c1]
    msub = m8[r0:r1, c0:c1] > 0
    curve = _sweep(sub, msub, imax, i_end, (r0, c0), W)
    i_opt = _knee(curve)
    hsub, ncand = _final(sub, msub, i_opt, (r0, c0), W)
    full = None
    if full_mask:
        full = np.zeros((H, W), np.uint8)
        full[r0:r1, c0:c1] = hsub
    seg = Segmentation(
        True,
        None,
        mask=full,
        roi=(r0, r1, c0, c1),
        i_opt=i_opt,
        i_max=imax,
        i_min=imin,
        n_candidates=ncand,
        area=int(hsub.sum()),
        curve=curve,
        roi_mask=hsub,
    )
    return seg
