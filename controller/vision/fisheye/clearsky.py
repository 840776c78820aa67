"""How far the sky read around the glare is a clear sky's: the trust a camera's sky
calibration is given on a frame.

A camera's sky calibration (``sky_scale``, ``sky_calibration``; :func:`.skybg.calibrated_scale`)
is fitted on clear days: it scales the sky model's correction of the rim to what a clear
sky's aureole and gradient do there.  Under broken cloud the rings around the glare read a
cloud's edges as well, and the model's asymmetry is partly the cloud's; the clear sky's
scale says nothing about that part, and amplifying it (by 1.6-2.8 on the third renderer)
moved visible suns by the cloud's share and had them refused.  A clear sky is smooth in
azimuth around the sun: a ring's means are its level, a dipole (the gradient) and a
little quadrupole.  A cloud's edge puts structure at every order.  So each outer ring's ray
means (1.7-3.2 rim radii: closer in, the glare's own steep profile read about an axis still
off its centre leaves structure of its own) are fitted with harmonics up to the second,
and what they leave (RMS over the rings' rays) is set against the rings' dipole (RMS over
the rings), floored at :data:`DIPOLE_FLOOR` of the glare's contrast (a high sun's dipole is
small, and so is what its scale changes).  That ratio is the rings' roughness; the
calibration's departure from 1 is kept in full up to a roughness ``lo``, falls linearly to
none at ``hi``, and beyond it the sky model is applied as it is (:func:`trusted_scale`).
:func:`.glare.fit_glare` judges the rings from its second reading on (the first is read
about the candidate's rough centre).

On the third renderer's clear days a calibrated camera's readings after the first read at
most 0.14 (the first, up to 0.20); under its broken cloud, the visible suns a calibrated
camera lost and the uncalibrated one found read 0.2-1.2 (all six rings), half over 0.7.
The one ``sky_scale`` is not judged: its bundles leave the CCD smear's column in the rings,
which reads 0.3 on the third renderer's clear days.
"""

from __future__ import annotations

import math

import numpy as np

from .skybg import harmonic_design
from .small import median_kept, median_rows

#: the rings' bands, in rim radii (the outer ones of :func:`.skybg.sky_dipole`)
RING_BANDS = ((1.7, 2.0), (2.0, 2.4), (2.4, 2.8), (2.8, 3.2))
#: the rings' dipole is counted as at least this fraction of the glare's contrast
DIPOLE_FLOOR = 0.05
#: rays a ring needs (all of their samples on the sky) for its harmonics to be fitted
MIN_RING_RAYS = 12


def ring_roughness(
    vals: np.ndarray,
    chi: np.ndarray,
    phi: np.ndarray,
    rho: float,
    rays_ok: np.ndarray,
    sky: np.ndarray,
    contrast: float,
) -> float | None:
    """The rings' structure beyond a clear sky's harmonics, over their dipole (dimensionless).

    Parameters
    ----------
    vals : ndarray, shape (n_rays, n_chi)
        The rings' samples, in the sky model's units (grey levels, or light).
    chi : ndarray, shape (n_chi,)
        Each sample's angle from the axis (rad).
    phi : ndarray, shape (n_rays,)
        Each ray's angle about the axis (rad).
    rho : float
        The rim's radius (rad).
    rays_ok : ndarray of bool, shape (n_rays,)
        The rays that count (a streak's are left out).
    sky : ndarray of bool, shape (n_rays, n_chi)
        The samples that look at the sky.
    contrast : float
        The glare's peak less the sky (the sky model's units).

    Returns
    -------
    float or None
        RMS of the rings' ray means about their fit by harmonics 0-2, over the RMS of the
        fitted dipole's amplitude (at least :data:`DIPOLE_FLOOR` times ``contrast``); None
        when no ring has :data:`MIN_RING_RAYS` rays wholly on the sky.
    """
    good = sky & rays_ok[:, None] & np.isfinite(vals)
    # each band a run of columns (``chi`` ascends): its rays' means and whether all of a
    # ray's samples count, reduced at once; then each band's harmonics by its own normal
    # equations, all bands in one batch
    cuts = np.searchsorted(chi, np.array(RING_BANDS) * rho).ravel()
    lo, hi = cuts[0::2], cuts[1::2]
    bands = hi - lo >= 2
    if not bands.any():
        return None
    at = np.stack([lo[bands], hi[bands]], axis=1).ravel()
    R, C = vals.shape
    pad = np.zeros((R, C + 1))
    pad[:, :C] = np.where(good, vals, 0.0)
    M = (np.add.reduceat(pad, at, axis=1)[:, ::2] / (hi - lo)[bands]).T  # (bands, rays)
    ok_pad = np.ones((R, C + 1), bool)
    ok_pad[:, :C] = good
    ok = np.logical_and.reduceat(ok_pad, at, axis=1)[:, ::2].T  # (bands, rays)
    fitted = ok.sum(axis=1) >= MIN_RING_RAYS
    if not fitted.any():
        return None
    W, M = ok[fitted].astype(float), M[fitted]
    A, _ = harmonic_design(np.ascontiguousarray(phi, dtype=np.float64).tobytes())
    coef = np.linalg.solve((A.T[None, :, :] * W[:, None, :]) @ A, ((W * M) @ A)[..., None])[..., 0]
    res = M - coef @ A.T
    res2 = list((W * res * res).sum(axis=1) / W.sum(axis=1))
    dip2 = list(coef[:, 1] ** 2 + coef[:, 2] ** 2)
    if not res2:
        return None
    dip = max(math.sqrt(float(np.mean(dip2))), DIPOLE_FLOOR * max(contrast, 0.0), 1e-9)
    return math.sqrt(float(np.mean(res2))) / dip


def clear_sky_trust(roughness: float | None, lo: float, hi: float) -> float:
    """The trust (0-1) in a clear sky around the glare: 1 up to a ``roughness`` of ``lo``,
    falling linearly to 0 at ``hi`` (:func:`ring_roughness`; dimensionless); 1 when the
    rings could not be judged (None)."""
    if roughness is None:
        return 1.0
    if hi <= lo:
        return 1.0 if roughness <= lo else 0.0
    return float(np.clip((hi - roughness) / (hi - lo), 0.0, 1.0))


def trusted_scale(scale: float, trust: float) -> float:
    """A camera's sky scale (dimensionless) applied in proportion to the ``trust`` in a
    clear sky (0-1): ``1 + (scale - 1) trust``, the sky model as it is with no trust."""
    return 1.0 + (scale - 1.0) * trust


#: a ring sample further than this many robust sigmas from its ring's clear-sky harmonics is
#: a cloud's (:func:`cloud_edges`)
CLOUD_K = 4.0
#: that sigma's floor: this fraction of the ring's level, plus half a unit of the samples
CLOUD_FLOOR = 0.03
#: rounds of refitting a ring's harmonics without the samples it flags
CLOUD_ROUNDS = 6


def cloud_edges(vals: np.ndarray, ok: np.ndarray, phi: np.ndarray, bright: bool = True) -> np.ndarray:
    """The ring samples a cloud's edge sets apart from a clear sky, and every sample beyond
    them along their ray.

    A clear sky is smooth around the glare: each ring (a column of ``vals``) is its level, a
    dipole and a little quadrupole in the ray angle (as :func:`ring_roughness` fits them).  A
    cloud that crosses the rings (its thick body dark against the aureole, its thin edge
    bright) is a run of rays far off that fit.  Each ring's harmonics are fitted from its
    median level, dropping the samples beyond :data:`CLOUD_K` robust sigmas (floored at
    :data:`CLOUD_FLOOR` of the level) and refitting, :data:`CLOUD_ROUNDS` times at most; a
    ray is flagged from its first such sample outwards (a cloud goes on beyond its edge:
    flagging the edge alone left the third renderer's clouds at 0.252 deg RMS, against 0.235).
    The sky models of :mod:`.skybg` then read the sky around the cloud: they had taken its
    edge for the sky's gradient and carried it to the rim.  ``bright=False`` flags the dark
    side only (a bloom's dome over the glare is no cloud's sunlit edge).

    Parameters
    ----------
    vals : ndarray, shape (n_rays, n_chi)
        The rings' samples (grey levels, or light), ``chi`` ascending along the columns.
    ok : ndarray of bool, same shape
        The samples that count (on the sky, on a ray that counts, finite).
    phi : ndarray, shape (n_rays,)
        Each ray's angle about the axis (rad).
    bright : bool
        Flag samples above the fit as well as below it.

    Returns
    -------
    ndarray of bool, same shape as ``vals``
        True where a sample is a cloud's or lies beyond one on its ray.  A ring with fewer
        than :data:`MIN_RING_RAYS` samples that count flags none; on a ring of level 73 whose
        dipole is 7, a 4-ray edge 50 above it is flagged, one 40 above it is not (the tests).
    """
    bad = np.zeros(vals.shape, bool)
    cols = np.flatnonzero(ok.sum(axis=0) >= MIN_RING_RAYS)
    if cols.size == 0:
        return bad
    W = ok[:, cols].T  # (rings, rays)
    M = np.where(W, vals[:, cols].T, 0.0)
    A, pinv_t = harmonic_design(np.ascontiguousarray(phi, dtype=np.float64).tobytes())
    if W.all():  # a clear sky's rings: least squares leave no sample beyond half the limit
        fit = M @ pinv_t  # (a cloud bends this fit towards it: hence half)
        res = np.abs(M - fit @ A.T)
        floor = CLOUD_FLOOR * np.abs(median_rows(M)) + 0.5
        if not (res > (0.5 * CLOUD_K * (1.4826 * median_rows(res) + floor))[:, None]).any():
            return bad
    coef = np.zeros((cols.size, A.shape[1]))
    coef[:, 0] = median_kept(M, W)  # a robust start: a least-squares one bends to the cloud
    floor = CLOUD_FLOOR * np.abs(coef[:, 0]) + 0.5
    keep = W
    active = np.ones(cols.size, bool)
    for _ in range(CLOUD_ROUNDS):
        res = np.abs(M - coef @ A.T)
        limit = CLOUD_K * (1.4826 * median_kept(res, keep) + floor)
        new = W & (res <= limit[:, None])
        active &= new.sum(axis=1) >= MIN_RING_RAYS  # too few left: the last fit stands
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        w = new[rows].astype(float)
        try:
            coef[rows] = np.linalg.solve((A.T[None] * w[:, None, :]) @ A, ((w * M[rows]) @ A)[..., None])[
                ..., 0
            ]
        except np.linalg.LinAlgError:  # a ring's kept rays all but collinear: its fit stands
            break
        done = (new[rows] == keep[rows]).all(axis=1)
        keep = keep.copy()
        keep[rows] = new[rows]
        active[rows[done]] = False
        if not active.any():
            break
    signed = M - coef @ A.T
    limit = CLOUD_K * (1.4826 * median_kept(np.abs(signed), keep) + floor)
    out = np.abs(signed) > limit[:, None] if bright else signed < -limit[:, None]
    bad[:, cols] = (W & out).T
    return np.logical_or.accumulate(bad, axis=1)
