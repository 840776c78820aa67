"""The sky behind a glare's rim: read on rings outside it, and each ray's rim level raised by it.

A sky brighter on one side of the glare shifts the rim's isophote towards that side.
:func:`read_sky` reads the rings just outside the rim around the current axis (the
background level, its dipole, or its model by elevation where the rings are cut by the
horizon; :mod:`.skybg`), and :func:`rim_levels` raises each ray's rim level by what that sky
adds there, so that the rim is taken where the glare alone reaches the level
(:func:`.glare.fit_glare`, step 2; docs/fisheye.md, step 4).

Conventions: ``geometry`` is a :data:`.streak.RimGeometry` ``(lens, a, e1, e2, phi, rho)``,
the axis ``a`` (unit, camera frame), its tangents ``e1``, ``e2``, the rays' angles ``phi``
about it (from e1 towards e2) and the rim's angular radius ``rho`` (rad); ``up_cam`` the
zenith in the camera frame (None: orientation unknown).  Levels are grey unless said; the
sky model's units are grey, or light with a :class:`.radiometry.Radiometry`.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .blend import blended_excess
from .clearsky import clear_sky_trust, cloud_edges, ring_roughness, trusted_scale
from .radiometry import Radiometry, illumination_about, rim_shift
from .rings import SkyReading
from .skybg import calibrated_scale, sky_by_elevation, sky_dipole
from .small import clip_unit, gradient, median
from .streak import RimGeometry

if TYPE_CHECKING:
    from .glare import GlareOptions

_COS_60DEG = 0.5


@dataclass(frozen=True)
class SkyBehind:
    """One reading of the sky around a glare (:func:`read_sky`); the default is no reading."""

    bg: float = 0.0  # the sky's level next to the rim (grey)
    bg_s: float = 0.0  # the same in the sky model's units
    top_s: float = 0.0  # the glare's peak in those units
    dipole: np.ndarray = field(default_factory=lambda: np.zeros(2))  # :func:`.skybg.sky_dipole`
    by_el: np.ndarray | None = None  # :func:`.skybg.sky_by_elevation`: rings cut by the horizon
    trust: float = 1.0  # how far the camera's sky calibration applies (:mod:`.clearsky`)
    reading: SkyReading | None = None  # the rings themselves (:mod:`.rings`)
    inside: bool = False  # the innermost rings at or above the rim's level: read inside the glare


def read_sky(
    rings: tuple[np.ndarray, np.ndarray],
    chi: np.ndarray,
    geometry: RimGeometry,
    rays_ok: np.ndarray,
    dirs_up: np.ndarray | None,
    peak: float,
    opts: GlareOptions,
    before: SkyBehind,
    *,
    first: bool,
    streak_free: bool,
    alpha: float,
    dpp: float,
    up_cam: np.ndarray | None,
    radiometry: Radiometry | None,
) -> SkyBehind | None:
    """The sky read on ``rings`` (grey samples, whether each looks at the sky; n_rays x n_chi)
    at angles ``chi`` (rad) from the axis along ``geometry``'s rays, of which ``rays_ok``
    count (``dirs_up``: their directions at the axis dotted with ``up_cam``), around a glare whose peak is ``peak`` (grey); None when too few of the outer
    rings' samples see the sky.

    ``before``: the last reading, whose ``trust`` stands unless this one judges it (from the
    second pass on, with a camera's sky calibration: the first, about the candidate's rough
    centre, sees the glare's own profile off centre).  ``first``: the fit's first pass (a
    sunlit cloud's bright edge is not told from the glare's there); ``streak_free``: no bloom
    streak (its dome is no cloud's edge); ``alpha``: the rim's blend of metrics so far
    (:mod:`.blend`; the rings are read at equal blended distance); ``dpp``: deg per pixel at
    the glare.
    """
    lens, a, e1, e2, phi, rho = geometry
    rvals, rsky = rings
    if radiometry is not None:  # the sky in light, as the centre's illumination sees it
        rvals = radiometry.to_light(rvals) / illumination_about(radiometry, a, e1, e2, phi, chi)
    if alpha > 0.0:  # the rings at equal blended distance, to first order
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            prof = np.nanmean(np.where(rsky, rvals, np.nan), axis=0)
        if np.isfinite(prof).all():
            exc = blended_excess(lens, a, e1, e2, phi, chi, alpha, math.radians(dpp))
            rvals = rvals - gradient(prof, chi)[None, :] * exc
    outer = rvals[:, -3:][rsky[:, -3:] & np.isfinite(rvals[:, -3:])]
    if outer.size < 8:
        return None
    bg = median(outer)  # in the sky model's units
    top_s = peak if radiometry is None else float(radiometry.to_light(peak))
    # the sky models read the sky around a cloud's edge; a bloom's dome is no edge
    ok_r = rsky & rays_ok[:, None] & np.isfinite(rvals) & opts.cloud_edges
    clear = rsky & ~cloud_edges(rvals, ok_r, phi, bright=not first and streak_free)
    dipole = sky_dipole(rvals, chi, phi, rho, rays_ok, top_s - bg, clear)
    # the rings' fix (.rings) leaves a cloud's edge out too
    reading = SkyReading(rvals, chi, phi, rho, rays_ok, clear, a, e1, e2, top_s - bg)
    trust = before.trust
    if not first and opts.sky_calibration is not None:  # judged once centred (see GlareOptions)
        rough = ring_roughness(rvals, chi, phi, rho, rays_ok, rsky, top_s - bg)
        trust = clear_sky_trust(rough, *opts.clear_sky_roughness)
    by_el = None
    if up_cam is not None and dirs_up is not None and not rsky.all():
        # rings cut by the horizon: model the sky by elevation instead of a dipole
        up_a = min(max(float(a @ up_cam), -1.0), 1.0)
        sin_el = np.cos(chi)[None, :] * float(a @ up_cam) + np.sin(chi)[None, :] * dirs_up[:, None]
        xr = (np.arcsin(np.clip(sin_el, -1, 1)) - math.asin(up_a)) / rho
        by_el = sky_by_elevation(rvals, chi, phi, rho, rays_ok, clear, xr, top_s - bg)
    bg_s = bg
    if radiometry is not None:
        bg = float(radiometry.to_grey(bg_s))
    near = chi < 1.4 * rho
    inner = rings[0][:, near][rsky[:, near]]
    inside = inner.size > 0 and median(inner) >= bg + opts.level * (peak - bg)
    return SkyBehind(bg, bg_s, top_s, dipole, by_el, trust, reading, bool(inside))


def rim_levels(
    sky: SkyBehind,
    geometry: RimGeometry,
    dirs_up: np.ndarray | None,
    peak: float,
    opts: GlareOptions,
    up_cam: np.ndarray | None,
    radiometry: Radiometry | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each ray's rim level (grey), the sky's raise of it (grey) and that raise in the sky
    model's units, for the rays of ``geometry`` (``dirs_up``: their directions at the axis
    dotted with ``up_cam``; see :class:`.glare.GlareOptions`: ``level``,
    ``sky_scale``, ``sky_calibration``, and the level lowered where the sky next to a low
    sun would clip, ``max_ray_level``, ``min_level``)."""
    lens, a, e1, e2, phi, rho = geometry
    if sky.by_el is not None and up_cam is not None and dirs_up is not None:
        up_a = min(max(float(a @ up_cam), -1.0), 1.0)
        sin_k = math.cos(rho) * float(a @ up_cam) + math.sin(rho) * dirs_up
        xk = (np.arcsin(clip_unit(sin_k)) - math.asin(up_a)) / rho
        shift = sky.by_el[0] * xk + sky.by_el[1] * xk**2 + sky.by_el[2] * xk**3
    else:
        shift = sky.dipole[0] * np.cos(phi) + sky.dipole[1] * np.sin(phi)
    k_cam = calibrated_scale(opts.sky_calibration, sky.by_el is not None, a, up_cam)
    k_sky = opts.sky_scale * trusted_scale(k_cam, sky.trust)  # the calibration, as far as the sky is clear
    shift_s = k_sky * shift * np.ones(len(phi))  # in the sky model's units
    # keep every ray's level under the clip, so that the rim stays whole (see GlareOptions)
    bg, contrast = sky.bg, peak - sky.bg
    shift = rim_shift(radiometry, shift_s, bg + opts.level * contrast, a, e1, e2, phi, rho)
    top = horizon_side_excess(shift, phi, a, e1, e2, up_cam) / max(contrast, 1e-6)
    f_level = min(opts.level, max(opts.max_ray_level - top, opts.min_level))
    if f_level != opts.level:
        shift = rim_shift(radiometry, shift_s, bg + f_level * contrast, a, e1, e2, phi, rho)
    return bg + f_level * contrast + shift, shift, shift_s


def horizon_side_excess(
    shift: np.ndarray,
    phi: np.ndarray,
    a: np.ndarray,
    e1: np.ndarray,
    e2: np.ndarray,
    up_cam: np.ndarray | None,
) -> float:
    """The sky's largest raise of a ray's level (grey levels) when that ray points within
    60 deg of the horizon (down the vertical through the glare), else 0.

    ``shift``: each ray's raise; ``phi``: the rays' angles about the axis ``a`` in the
    tangent basis (``e1``, ``e2``); ``up_cam``: the zenith in the camera frame.  The clear
    sky next to a low sun brightens towards the horizon, and that is the side where the rim
    clips; a raise on another side is a cloud's, which a lower rim would follow into the
    cloud.  Without the orientation the horizon is unknown: 0.
    """
    if up_cam is None or shift.size == 0:
        return 0.0
    k = int(np.argmax(shift))
    if not faces_horizon(float(phi[k]), a, e1, e2, up_cam):
        return 0.0
    return max(float(shift[k]), 0.0)


def faces_horizon(
    phi: float, a: np.ndarray, e1: np.ndarray, e2: np.ndarray, up_cam: np.ndarray | None
) -> bool:
    """Whether the ray at angle ``phi`` about the axis ``a`` (tangent basis ``e1``, ``e2``)
    points within 60 deg of down the vertical through it (False without the orientation)."""
    if up_cam is None:
        return False
    ray = math.cos(phi) * e1 + math.sin(phi) * e2
    down = float(up_cam @ a) * a - up_cam  # the zenith's opposite, in the tangent plane
    n = float(np.linalg.norm(down))
    return n >= 1e-9 and float(ray @ down) >= n * _COS_60DEG
