"""The sun placed by the sky's rings alone, for a camera whose sky is a product.

A clear sky's radiance is an indicatrix of the angle to the sun times a gradation by the
zenith angle (the CIE general skies, Perez).  Where the circumsolar aureole carries that
product out to the glare's rim, the gradation shifts the rim's isophote along the
vertical, and :func:`.skybg.sky_dipole`'s additive model of the sky at the rim falls short
(a third renderer's suns read 0.11 deg low).  In log light such a sky is a level per ring
around the sun plus a function of elevation, which the rings outside the rim measure
without extrapolating to it; the glare's own profile, read about an axis ``eps`` off the
sun's, adds ``-d ln P / d chi`` times ``eps`` (as in :func:`.skybg.sky_by_elevation`, there
in light).  Where the rim is the lens's glare, whose halo fills the inner rings without the
gradation, the same fit is 0.03-0.12 deg off; no frame tells the two apart
(docs/fisheye-rounds.md, a twenty-fourth round), so where the sun lies between the two
fixes is the camera's to learn (:mod:`.locator`).

Conventions: ``eps`` along the tangent vectors (e1, e2) at the reading's axis (rad); ray
angle ``phi`` from e1 towards e2; directions are unit vectors in the camera frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .clearsky import ring_roughness
from .skybg import RING_EDGES
from .small import gradient, median

#: rounds of clipping the fit's outliers (3 MADs; it stops once they stop changing)
MAX_CLIP_ROUNDS = 8
#: the rings' light by elevation has a knot every KNOT_DEG of elevation (:func:`_elevation_basis`)
KNOT_DEG = 5.0
#: the rings' fix is not used where it lies farther than this from the reading's axis, the
#: rim's fix of the pass before (deg): the product sky's correction of the rim is 0.2 deg at
#: most on the third renderer's clear days
MAX_SHIFT_DEG = 0.3
#: nor farther than this share of the rim's radius, where it is more than MAX_SHIFT_DEG
#: (0.3 deg of a 4-deg rim): the sky's shift of the rim grows with the radius (the second
#: renderer's 5-deg wide glare, rims of 5.6-6.4 deg: the rim's and the rings' fixes up to
#: 0.43 deg apart, the sun between them); only where the rings are smoother than
#: SMOOTH_ROUGHNESS (that glare's 0.035-0.042; it let in four of the third renderer's
#: cloudy rings, at 0.11-0.31, two of them 0.29 and 0.49 deg off)
SHIFT_PER_RHO, SMOOTH_ROUGHNESS = 0.075, 0.1
#: with the site (the ephemeris gate behind the fix) that share grows with the air mass over
#: SHIFT_AIRMASS_REF (the sun 42 deg high), SHIFT_AIRMASS_MAX times at most: around a low sun
#: the sky is most of the light at the rim (the fourth renderer's suns at 17-25 deg, rims of
#: 4-6 deg and rings at roughness 0.05-0.08: the two fixes 0.25-0.8 deg apart, the sun about
#: a third of the way from the rim, read 0.19 deg RMS by the rim alone, 0.07 so).  Without
#: the site the sun's own path chooses between the two fixes, and wider bounds let a cloudy
#: sequence's low rings sway that choice (the third renderer's clear frames after its
#: clouds: 0.0215 -> 0.0557 deg)
SHIFT_AIRMASS_REF, SHIFT_AIRMASS_MAX = 1.5, 2.0
#: nor where the rings are rougher than a clear sky's (:func:`.clearsky.ring_roughness`;
#: the third renderer's clear days read up to 0.30 with its CCD smear's column in them)
MAX_ROUGHNESS = 0.35


@dataclass(frozen=True)
class SkyReading:
    """The rings of a fit's last reading of the sky (:func:`.glare.fit_glare`).

    ``vals`` (n_rays, n_chi): samples in the sky model's units (grey, or light);
    ``chi`` (rad) their angles from ``axis``; ``phi`` the rays' angles about it; ``rho`` the
    rim's radius (rad); ``rays_ok``, ``sky``: the rays that count and the samples that look
    at the sky; ``e1``, ``e2`` the tangent basis at ``axis``; ``contrast``: the glare's peak
    less the sky, in the same units.
    """

    vals: np.ndarray
    chi: np.ndarray
    phi: np.ndarray
    rho: float
    rays_ok: np.ndarray
    sky: np.ndarray
    axis: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    contrast: float


def log_ring_offset(reading: SkyReading, x: np.ndarray) -> np.ndarray | None:
    """The sun's offset from the reading's axis that its rings' log light places it at (rad,
    along e1, e2).

    Model of each ray's mean of ``ln vals`` over each ring (:data:`.skybg.RING_EDGES`): a
    level per ring, ``-d ln P / d chi * (eps_1 cos phi + eps_2 sin phi)`` with ``P`` the
    rings' mean profile, and the sky's light by elevation (:func:`_elevation_basis`), ``x``
    each sample's elevation less the axis's over ``rho`` (same shape as ``vals``).  Least
    squares, clipped at 3 MADs until the kept rows stop changing; then once more with ``P``
    read from the samples less the fitted light by elevation, whose curvature across a wide
    ring otherwise leaks into ``P``'s slope and so into the scale of ``eps``.  A ray's ring
    counts where all its samples are on the sky and positive; a ring needs 6 such rays, the
    fit 3 rings.  None when there is too little sky.
    """
    vals, chi, phi, rho = reading.vals, reading.chi, reading.phi, reading.rho
    good = reading.sky & reading.rays_ok[:, None] & np.isfinite(vals) & (vals > 0.0)
    if int(np.count_nonzero(good)) < 30:
        return None
    lv = np.log(np.where(good, vals, 1.0))
    n_col = good.sum(axis=0)
    if not (n_col > 0).all():
        return None
    edges = np.searchsorted(chi, np.array(RING_EDGES) * rho)
    lo, hi = edges[:-1], edges[1:]
    wide = hi - lo >= 2
    if int(np.count_nonzero(wide)) < 3:
        return None
    lo, hi = lo[wide], hi[wide]
    at = np.stack([lo, hi], axis=1).ravel()
    n = (hi - lo).astype(float)

    def ring_sums(a: np.ndarray) -> np.ndarray:
        return np.add.reduceat(np.concatenate([a, a[..., :1] * 0], axis=-1), at, axis=-1)[..., ::2]

    ok = np.logical_and.reduceat(np.concatenate([good, good[:, :1]], axis=1), at, axis=1)[:, ::2]
    used = np.flatnonzero(ok.sum(axis=0) >= 6)
    if used.size < 3:
        return None
    ray, ring = np.nonzero(ok[:, used])
    k = used.size
    basis = _elevation_basis(x, x[good], chi / rho, rho)
    m = basis.shape[0]
    # design: a level per ring (one-hot), the glare's shift, the light by elevation; solved
    # by its normal equations (k + 2 + m unknowns, ~200 rows)
    n_par = k + 2 + m
    A = np.zeros((ray.size, n_par))
    A[np.arange(ray.size), ring] = 1.0
    A[:, k + 2 :] = (ring_sums(basis)[:, :, used] / n[used])[:, ray, ring].T
    y = (ring_sums(lv)[:, used] / n[used])[ray, ring]
    if y.size < 2 * n_par:
        return None

    def solve(lv_of: np.ndarray) -> np.ndarray | None:
        d = (ring_sums(gradient((lv_of * good).sum(axis=0) / n_col, chi)) / n)[used][ring]
        A[:, k] = -d * np.cos(phi)[ray]
        A[:, k + 1] = -d * np.sin(phi)[ray]
        return _clipped_solve(A, y)

    sol = solve(lv)
    if sol is not None:  # again, P read less the light by elevation fitted
        sol = solve(lv - np.tensordot(sol[k + 2 :], basis, axes=1))
    return None if sol is None else sol[k : k + 2]


def _elevation_basis(x: np.ndarray, x_sky: np.ndarray, c: np.ndarray, rho: float) -> np.ndarray:
    """Columns (first axis) of the rings' light by elevation at samples ``x`` (elevation less
    the axis's, over ``rho``; ``c``: the rings' ``chi / rho``): a cubic in ``x`` with a knot
    every :data:`KNOT_DEG` of elevation over ``x_sky``'s span (the samples on the sky), and
    ``x (c - 1)`` for the glare's share of the inner rings, which dims the gradation there.
    A clear sky's gradation ``1 + a exp(b / cos Z)`` bends hardest 5-15 deg up; a wide glare's
    rings span 40 deg of it, which one cubic leaves 0.03-0.3 deg off the sun in log light
    alone (a product sky drawn on the third renderer's rings at 8-35 deg: 0.035 deg RMS with
    Perez's gradation, 0.134 with CIE sky 12's; 0.0037 and 0.0055 with the knots)."""
    step = math.radians(KNOT_DEG) / rho
    knots = np.arange(float(x_sky.min()) + step, float(x_sky.max()) - step / 2, step)
    out = np.empty((4 + knots.size, *x.shape))  # columns first: each a contiguous plane
    out[0] = x
    np.multiply(x, x, out=out[1])
    np.multiply(out[1], x, out=out[2])
    np.multiply(x, c[None, :] - 1.0, out=out[3])
    if knots.size:
        np.maximum(x[None] - knots[:, None, None], 0.0, out=out[4:])
        out[4:] **= 3
    return out


def _clipped_solve(A: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """Least squares of ``A sol = y`` by the normal equations, the rows more than 3 MADs off
    left out until they stop changing (:data:`MAX_CLIP_ROUNDS`); None when singular."""
    keep = np.ones(y.size, bool)
    sol = np.zeros(A.shape[1])
    for _ in range(MAX_CLIP_ROUNDS):
        Ak = A[keep]
        try:
            sol = np.linalg.solve(Ak.T @ Ak, Ak.T @ y[keep])
        except np.linalg.LinAlgError:  # a ring's kept rays all but collinear
            return None
        res = np.abs(y - A @ sol)
        mad = 1.4826 * median(res[keep]) + 1e-9
        new = res <= 3.0 * mad
        if (new == keep).all() or int(np.count_nonzero(new)) < 2 * A.shape[1]:
            break
        keep = new
    return sol


def ring_direction(reading: SkyReading, up_cam: np.ndarray, by_airmass: bool = False) -> np.ndarray | None:
    """The sun's direction placed by ``reading``'s rings (:func:`log_ring_offset`), or None
    when they are too few, too rough for a clear sky, or place it farther than
    :data:`MAX_SHIFT_DEG` from the reading's axis (:data:`SHIFT_PER_RHO` of the rim's radius
    when that is more and the rings are smooth; ``by_airmass``, with the site, that share
    grown by the air mass: :data:`SHIFT_AIRMASS_REF`).  ``up_cam``: the zenith in the camera
    frame."""
    r = reading
    rough = ring_roughness(r.vals, r.chi, r.phi, r.rho, r.rays_ok, r.sky, r.contrast)
    if rough is None or rough > MAX_ROUGHNESS:
        return None
    up_a = min(max(float(r.axis @ up_cam), -1.0), 1.0)
    dirs_up = np.cos(r.phi) * float(r.e1 @ up_cam) + np.sin(r.phi) * float(r.e2 @ up_cam)
    sin_el = np.cos(r.chi)[None, :] * up_a + np.sin(r.chi)[None, :] * dirs_up[:, None]
    x = (np.arcsin(np.clip(sin_el, -1.0, 1.0)) - math.asin(up_a)) / r.rho
    eps = log_ring_offset(r, x)
    grow = min(max(1.0 / max(up_a, 0.05) / SHIFT_AIRMASS_REF, 1.0), SHIFT_AIRMASS_MAX) if by_airmass else 1.0
    bound = (
        MAX_SHIFT_DEG
        if rough > SMOOTH_ROUGHNESS
        else max(MAX_SHIFT_DEG, SHIFT_PER_RHO * grow * math.degrees(r.rho))
    )
    if eps is None or math.degrees(math.hypot(eps[0], eps[1])) > bound:
        return None
    d = r.axis + eps[0] * r.e1 + eps[1] * r.e2
    return d / np.linalg.norm(d)
