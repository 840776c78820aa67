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


def _inliers(err: np.ndarray, keep: np.ndarray, min_used: int) -> np.ndarray | None:
    """The detections whose angle ``err`` (deg) is within 3 MAD (at least 0.05 deg) over the
    median of those in ``keep``; None when that changes nothing or leaves under ``min_used``."""
    med = float(np.median(err[keep]))
    mad = 1.4826 * float(np.median(np.abs(err[keep] - med)))
    new = err <= med + max(3.0 * mad, 0.05)
    if new.sum() < min_used or np.array_equal(new, keep):
        return None
    return new


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
        new = _inliers(_angles(R, _unit(d1 + (k - 1.0) * m), s), keep, min_used)
        if new is None:
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


#: the air mass term is held at this elevation's below it (as in the pipeline)
MIN_CAL_EL_DEG = 5.0
#: a sky model seen on fewer frames than this keeps its one scale, without the air mass term
MIN_PER_MODEL = 6


@dataclass(frozen=True)
class SkyCalibrationFit:
    """Result of :func:`fit_sky_calibration` (angles in degrees)."""

    coefficients: tuple[float, float, float, float]  # (k0, k1) of the dipole, then by elevation
    adopted: bool  # it cut the residual it is compared with by MIN_GAIN
    residual_deg: float  # RMS angle over the inliers, rotation and calibration fitted together
    residual_compared_deg: float  # what it had to beat (the bundle's fit without it)
    enu_from_camera: np.ndarray
    used: int


def _air_mass_less_one(s: np.ndarray) -> np.ndarray:
    el = np.maximum(np.arcsin(np.clip(s[:, 2], -1.0, 1.0)), np.radians(MIN_CAL_EL_DEG))
    return 1.0 / np.sin(el) - 1.0


def fit_sky_calibration(
    times: Sequence[float],
    d_unscaled: np.ndarray,
    d_scaled: np.ndarray,
    step: float,
    by_elevation: Sequence[bool],
    site: Site,
    compared_deg: float,
    *,
    scale: float = 1.0,
    min_used: int = 12,
    iters: int = 60,
) -> SkyCalibrationFit:
    """A scale for each of the two sky models (the dipole, the model by elevation), each
    linear in the air mass less one, ``k0 + k1 (1 / sin(el) - 1)``, fitted with the rotation.

    As :func:`fit_sky_scale`, with frame ``i``'s scale ``k_i = A_i . p`` (``A_i``: the
    columns of its model, 1 and the air mass less one of pvlib's sun, held under 5 deg):
    ``d_i(p) = d_i(1) + (k_i - 1) m_i``; Kabsch's rotation for a given ``p``, a linear least
    squares in ``p`` for a given rotation, alternated.  A model seen on fewer than
    ``MIN_PER_MODEL`` frames keeps ``scale`` (the one sky scale adopted), one seen over less
    than 0.3 of air mass has no air mass term.  It is
    adopted when its residual is at most ``1 - MIN_GAIN`` of ``compared_deg`` (the residual
    of the bundle's fit without it) and every frame's scale lies within ``SCALE_BOUNDS``.

    Parameters
    ----------
    d_unscaled, d_scaled, step : as for :func:`fit_sky_scale` (the frames measured with
        their column smear taken off).
    by_elevation : per frame, the sky was modelled by elevation (its flag
        ``sky_by_elevation``), not by the dipole.
    """
    d1 = _unit(np.asarray(d_unscaled, float).reshape(-1, 3))
    d2 = _unit(np.asarray(d_scaled, float).reshape(-1, 3))
    e = np.asarray(by_elevation, bool)
    if not (len(d1) == len(d2) == len(times) == len(e)):
        raise InputError("sky calibration: the detections, flags and times differ in length")
    if len(d1) < min_used:
        raise InputError(f"sky calibration: {len(d1)} sun detections, need >= {min_used}")
    m = (d2 - d1) / float(step)
    s = sun_vectors(site, times)
    x = _air_mass_less_one(s)
    cols = []
    for model in (~e, e):
        free = model.sum() >= MIN_PER_MODEL
        cols += [(model.astype(float), free), (model * x, free and float(np.ptp(x[model])) >= 0.3)]
    A = np.stack([c for c, _ in cols], 1)
    use = np.array([f for _, f in cols])
    p0 = np.array([scale, 0.0, scale, 0.0])  # what a term without its frames keeps

    def solve(keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = p0.copy()
        R = kabsch(d1[keep], s[keep])
        fixed = (A[keep][:, ~use] @ p0[~use])[:, None]
        for _ in range(iters):
            Rm, Rd = m[keep] @ R.T, d1[keep] @ R.T
            M = (A[keep][:, None, use] * Rm[:, :, None]).reshape(-1, int(use.sum()))
            q = np.linalg.lstsq(M, (s[keep] - Rd + Rm - fixed * Rm).reshape(-1), rcond=None)[0]
            p_new = p0.copy()
            p_new[use] = q
            R = kabsch(_unit(d1[keep] + (A[keep] @ p_new - 1.0)[:, None] * m[keep]), s[keep])
            done = float(np.abs(p_new - p).max()) < 1e-5
            p = p_new
            if done:
                break
        return R, p

    keep = np.ones(len(d1), bool)
    R, p = solve(keep)
    for _ in range(5):
        new = _inliers(_angles(R, _unit(d1 + (A @ p - 1.0)[:, None] * m), s), keep, min_used)
        if new is None:
            break
        keep = new
        R, p = solve(keep)
    k = A @ p
    res = float(np.sqrt(np.mean(_angles(R, _unit(d1 + (k - 1.0)[:, None] * m), s)[keep] ** 2)))
    bounded = bool(np.all((k[keep] >= SCALE_BOUNDS[0]) & (k[keep] <= SCALE_BOUNDS[1])))
    return SkyCalibrationFit(
        coefficients=(float(p[0]), float(p[1]), float(p[2]), float(p[3])),
        adopted=bounded and res <= (1.0 - MIN_GAIN) * compared_deg,
        residual_deg=res,
        residual_compared_deg=float(compared_deg),
        enu_from_camera=R,
        used=int(keep.sum()),
    )
