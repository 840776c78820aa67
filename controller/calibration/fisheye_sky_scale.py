"""The sky camera's sky-correction scale, fitted with its rotation from a day of sun sights.

The default fisheye pipeline raises each ray's rim level by the sky's asymmetric part,
read in rings outside the glare and extrapolated to the rim (:mod:`controller.vision.fisheye.skybg`).
How far that extrapolation falls short depends on the aureole's shape, which is the
camera's and its sky's (a power-law aureole: about half; a CIE sky with a wide glare: a
sixth), and it leaves the detections biased along the sky's gradient, mostly in elevation,
by an amount that grows with the correction.  A day of detections against pvlib's sun tells
that bias apart from the rotation, as a day of sun vectors fixes the rotation: the bias
follows each frame's own correction, which a rotation cannot mimic.

Model: detection ``i`` made with the correction scaled by ``k`` is, to first order,
``d_i(k) = d_i(1) + (k - 1) m_i``, with ``m_i`` measured by detecting the frame at two
scales.  ``(R, k)`` minimise ``sum |R d_i(k) - s_i|^2``: for a given ``k`` Kabsch's
rotation, for a given ``R`` a linear least squares in ``k``; alternated until ``k`` stops
moving.  Detections off by more than three robust sigmas are dropped, as in
:func:`.fisheye_orientation.fit_orientation`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..sun.source import Site
from .fisheye_orientation import kabsch, sun_vectors

#: the scale is kept within these bounds (the bundle's)
SCALE_BOUNDS = (0.25, 4.0)
#: a fitted scale is adopted only when it cuts the rotation fit's residual by this share:
#: on the second renderer's look as described, whose sky model is right, the fits of single
#: days gave 0.97-1.00 and changed the other days' RMS by -0.002 to +0.002 deg
MIN_GAIN = 0.15


@dataclass(frozen=True)
class SkyScaleFit:
    """Result of :func:`fit_sky_scale` (angles in degrees)."""

    scale: float  # the scale adopted (1.0 when the fit did not earn its place)
    fitted: float  # the scale the joint fit found
    residual_deg: float  # RMS angle between R d_i(fitted) and s_i over the inliers
    residual_unscaled_deg: float  # the same for the rotation alone (scale 1)
    enu_from_camera: np.ndarray
    used: int
    rejected: int


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def _angles(R: np.ndarray, d: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum((d @ R.T) * s, axis=1), -1.0, 1.0)))


def _joint(d1: np.ndarray, m: np.ndarray, s: np.ndarray, iters: int = 50) -> tuple[np.ndarray, float]:
    k = 1.0
    R = kabsch(d1, s)
    for _ in range(iters):
        Rm, Rd = m @ R.T, d1 @ R.T
        k_new = 1.0 + float(np.sum(Rm * (s - Rd)) / max(float(np.sum(Rm * Rm)), 1e-18))
        k_new = float(np.clip(k_new, *SCALE_BOUNDS))
        R = kabsch(_unit(d1 + (k_new - 1.0) * m), s)
        if abs(k_new - k) < 1e-4:
            return R, k_new
        k = k_new
    return R, k


def fit_sky_scale(
    times: Sequence[float],
    d_unscaled: np.ndarray,
    d_scaled: np.ndarray,
    step: float,
    site: Site,
    *,
    min_used: int = 12,
) -> SkyScaleFit:
    """The sky-correction scale and the rotation that best put the detections on the sun.

    Parameters
    ----------
    times : POSIX seconds of the frames.
    d_unscaled, d_scaled : (N, 3) the frames' detections (camera frame, unit vectors) with
        the correction as it is and scaled by ``1 + step``.
    step : the scale's step between the two sets (e.g. 0.25).
    site : where the camera stands (pvlib's sun there is the reference).
    """
    d1 = _unit(np.asarray(d_unscaled, float).reshape(-1, 3))
    d2 = _unit(np.asarray(d_scaled, float).reshape(-1, 3))
    if len(d1) != len(d2) or len(d1) != len(times):
        raise InputError("sky scale: the two sets of detections and the times differ in length")
    if len(d1) < min_used:
        raise InputError(f"sky scale: {len(d1)} sun detections, need >= {min_used}")
    m = (d2 - d1) / float(step)
    s = sun_vectors(site, times)
    keep = np.ones(len(d1), bool)
    R, k = _joint(d1, m, s)
    for _ in range(5):
        err = _angles(R, _unit(d1 + (k - 1.0) * m), s)
        med = float(np.median(err[keep]))
        mad = 1.4826 * float(np.median(np.abs(err[keep] - med)))
        new = err <= med + max(3.0 * mad, 0.05)
        if new.sum() < min_used or np.array_equal(new, keep):
            break
        keep = new
        R, k = _joint(d1[keep], m[keep], s[keep])
    fitted = float(np.sqrt(np.mean(_angles(R, _unit(d1 + (k - 1.0) * m), s)[keep] ** 2)))
    R1 = kabsch(d1[keep], s[keep])
    unscaled = float(np.sqrt(np.mean(_angles(R1, d1[keep], s[keep]) ** 2)))
    adopt = fitted <= (1.0 - MIN_GAIN) * unscaled
    return SkyScaleFit(
        scale=k if adopt else 1.0,
        fitted=k,
        residual_deg=fitted,
        residual_unscaled_deg=unscaled,
        enu_from_camera=R if adopt else R1,
        used=int(keep.sum()),
        rejected=int((~keep).sum()),
    )
