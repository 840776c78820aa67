"""The sun's saturated glare: coarse candidates, sub-pixel rim, and a small circle on the sphere.

Method (see docs/fisheye.md):

1. **Candidates** (:mod:`.blobs`): the near-saturated blobs and their inscribed disks.
2. **Rim.**  From a centre, rays sample the grey image bilinearly every half pixel; the rim
   point of a ray is where it first falls below a level between the peak and the local
   sky (linear interpolation between samples).  The sky read on rings outside the rim
   (:mod:`.rimsky`: its dipole, or its model by elevation where the horizon cuts the rings)
   raises each ray's level by what it adds there (a sky brighter on one side would shift
   the rim).
   A column smear (a CCD's frame transfer, :mod:`.smear`) is taken off the samples with
   a camera's sky calibration (``smear``); a saturated streak (bloom, :mod:`.streak`) costs the rays that
   run into it, whose rims it hides: the near-vertical rays when it leaves both ways,
   those within 40 deg of its way when it leaves one way (their sky's rings too, and the
   sky's dipole is fitted on the rest of the circle).
3. **Cone.**  Rim points become unit vectors through the calibrated lens.  Points on a
   small circle of the sphere lie on a plane, ``a . v = cos(rho)``, fitted robustly
   (:func:`.sphere.fit_cone`: median / MAD rejection from all points and from a RANSAC
   circle), so arcs pushed out by a saturated cloud edge or pulled in by a cloud over part
   of the glare are outliers.  Working on the sphere makes the fit indifferent to the
   fisheye squeezing a glare round on the sky near the edge of the field.
4. **Blend.**  Part of a real glare is the lens's own (round on the sensor); the rim is
   then refitted as a circle in a blend of the sky's and the sensor's metrics
   (:mod:`.blend`), from the cone's inliers and from all points; the blend ``alpha`` is
   measured, and the sky's rings are read at equal blended distance in the next pass.
5. Rays are re-cast around the new axis until it stops moving (at most 8 passes); the
   sky's rings are read on the first two passes and again once the axis has settled, so
   that the fit ends on an axis the sky was read around.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .blend import ALPHA_PRIOR, ALPHA_SIGMA, fit_blend
from .blobs import core_fill
from .lens import FisheyeLens
from .radiometry import Radiometry
from .rimsky import SkyBehind, faces_horizon, read_sky, rim_levels
from .rings import SkyReading
from .sphere import CLIP_MARGIN, centre_move, fit_cone, sample_sphere, tangent_basis
from .streak import short_bloom_both_ways, streak_along, streak_along_at_core, streak_rays


@dataclass(frozen=True)
class GlareOptions:
    """Tuning of the rim measurement (dimensionless unless stated).

    level : where between the local sky (0) and the peak (1) a ray's rim is taken.
    step_px : sampling step along the rays (px).
    outlier_k : residuals beyond ``outlier_k`` robust sigmas are outliers.
    min_rays, max_rays : number of rays around a candidate.
    max_passes : rays are re-cast around the new axis until it stops moving, at most this
        many times (a glare cut by the horizon or a bloom streak may take more than a few).
    max_horizon_shift : near the horizon, where the sky behind the rim is modelled by
        elevation, a ray whose level the sky raises by more than this fraction of the
        glare's contrast is not used (the model extrapolates there, towards the horizon).
    max_ray_level, min_level : where the sky raises a ray on the horizon's side (within 60
        deg of down the vertical through the glare; :func:`.rimsky.horizon_side_excess`) above
        ``max_ray_level`` (a fraction of the contrast), the whole rim's level is lowered
        until it does not, but not under ``min_level``.  Next to a low sun the sky plus the
        glare clips on the horizon's side before the glare alone reaches ``level``: there
        the rim is gone from the frame, and a rim seen only on the other sides turns any
        error of its radius into one of its centre.  The floor keeps the rim in the glare's
        steep band: lower down, a sunlit cloud edge next to the sun pulls it (broken cloud:
        0.21 deg RMS with a floor of 0.55, 0.19 with 0.75).
    sky_reads, sky_settled_deg : the sky's rings are read around the axis of the first two
        passes, then again (up to ``sky_reads`` readings in all) at the start of a pass
        after one that moved the axis less than ``sky_settled_deg``, and the fit does not
        end on an axis the sky was not read around unless the readings are spent.  The sky
        model's term for the axis's error (``-P' eps``) is a linearisation about the axis
        it is read around (read on the first two passes only, a halo 0.6 deg off the sun at
        the second read 0.111 deg RMS; 0.049 read at every pass); read at every pass, a sky
        shaped by clouds changes with the axis and the fit need not settle, or is read 0.8
        deg off (docs/fisheye.md, step 4).  A reading after the second that moves the settled
        axis by more than ``sky_unsettled_deg`` is a cloud's, not a correction of the
        linearisation: the fit goes back to the settled axis and its sky (without it, a
        dimmed sun in our broken-cloud suite wandered 2.9 deg).  Not when that sky was read
        inside the glare (``drop_stale_sky``: its innermost ring at or above the rim's level,
        so it was read around a rim since outgrown; the second renderer's linear output, a
        17-deg sun fitted on a 2-deg core at first: 0.74 deg low, now 0.06).
    sky_scale : the sky's correction of each ray's rim level times this: a camera's, fitted
        with its rotation from a day of sun sights (bundle ``[orientation] sky_scale``;
        :func:`controller.calibration.fisheye_sky_scale.fit_sky_scale`).
    sky_calibration : ``(k0, k1)`` for the dipole, then for the model by elevation: the
        correction of the model in use times ``k0 + k1 (1 / sin(el) - 1)`` at the axis's
        elevation (bundle ``[orientation] sky_calibration``; :func:`.skybg.calibrated_scale`).
    clear_sky_roughness : (lo, hi): a camera's ``sky_calibration`` (fitted on clear days)
        is applied in full while the rings' roughness (:func:`.clearsky.ring_roughness`:
        their structure beyond harmonics 0-2 over their dipole) is at most ``lo``, in
        proportion down to none at ``hi``, where the rings read a cloud's edges
        (:mod:`.clearsky`).  Judged from the sky's second reading on: the first, about the
        candidate's rough centre, sees the glare's own profile off centre.  Not the one
        ``sky_scale``: its frames keep the CCD smear's column in the rings (no removal), which
        reads as roughness on a clear day.
    column_smear : a frame-transfer CCD's column smear is read far from the glare and taken
        off the rim's samples (:mod:`.smear`; on with a sky calibration, fitted so, or the site).
    cloud_edges : the sky models leave out a cloud's edge in the rings (:mod:`.clearsky`; with the site).
    blend_prior : the rim's blend's prior, mean and one-sigma (:mod:`.blend`; a camera's own once learned).
    column_bloom : measure the glare as one with a bloom both ways along the image's columns
        (the rays near the vertical left out, as for a streak both ways): a small glare's
        short spill, which its first measure shows (:attr:`GlareFit.short_bloom`).
    """

    level: float = 0.85
    step_px: float = 0.5
    outlier_k: float = 3.0
    min_rays: int = 48
    max_rays: int = 120
    noise_floor_px: float = 0.06
    max_horizon_shift: float = 0.10
    max_passes: int = 8
    max_ray_level: float = 0.90
    min_level: float = 0.75
    one_way_streaks: bool = True
    column_bloom: bool = False
    sky_reads: int = 3
    sky_settled_deg: float = 0.1
    sky_unsettled_deg: float = 0.25
    drop_stale_sky: bool = True
    sky_scale: float = 1.0
    sky_calibration: tuple[float, float, float, float] | None = None
    clear_sky_roughness: tuple[float, float] = (0.2, 0.5)
    column_smear: bool = False
    cloud_edges: bool = False
    blend_prior: tuple[float, float] = (ALPHA_PRIOR, ALPHA_SIGMA)


@dataclass
class GlareFit:
    """Result of fitting the rim of one glare candidate (angles in degrees)."""

    axis: np.ndarray  # unit sun direction, camera frame
    radius_deg: float
    rms_deg: float
    n_rays: int  # usable rays (those a bloom streak covers are not)
    n_valid: int
    n_inliers: int
    max_gap_deg: float  # largest angular gap between inlier rays around the centre
    centre_uv: tuple[float, float]
    radius_px: float
    peak: float
    background: float
    core_fill: float  # fraction of the disk's inner part at or above the level
    deg_per_px: float
    smear: str | None = None
    flags: list[str] = field(default_factory=list)
    image_share: float = 0.0  # how much the glare is round in the image rather than on the sky
    image_share_sigma: float = math.inf  # its one-sigma from the rim alone (:class:`.blend.BlendFit`)
    last_move_deg: float = 0.0  # how far the last pass moved the axis (unsettled if large)
    sky_move_deg: float = 0.0  # how far the sky's correction moved the rim's centre (fitted)
    sky_harmonic_deg: float = 0.0  # its first harmonic over the rim's rays (.default's rule)
    sky_gap: bool = False  # the largest gap faces the horizon (or the zenith, near it), no rim found
    one_way_streak: bool = False  # the rays towards a streak that leaves one way were left out
    short_bloom: bool = False  # its misses are a short bloom's both ways along the columns
    sky_reading: SkyReading | None = None  # the rings of the last reading (:mod:`.rings`)

    @property
    def inlier_fraction(self) -> float:
        return self.n_inliers / max(self.n_rays, 1)

    @property
    def contrast(self) -> float:
        return (self.peak - self.background) / max(self.peak, 1.0)


_SIN_RIM_MIN = math.sin(math.radians(2.5))
_RHO_MAX = math.radians(45.0)  # no glare is this wide (the judge refuses radii over 20 deg)


def _crossings(
    vals: np.ndarray, radii: np.ndarray, level: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First fall of each row of ``vals`` below its ``level`` after an unbroken run at or above
    it from the first sample; (radius by linear interpolation, found, the fall's slope in
    grey levels per unit of ``radii``)."""
    n, m = vals.shape
    above = vals >= level[:, None]
    below = ~above
    below[:, 0] = False
    j = np.argmax(below, axis=1)
    at = np.arange(0, n * m, m) + j  # each row's first fall, in the flattened rows
    has = below.ravel()[at] & above[:, 0]
    jj = np.minimum(np.maximum(j, 1), m - 1)
    flat = vals.ravel()
    v1, v2 = flat[at + (jj - j) - 1], flat[at + (jj - j)]
    has &= np.isfinite(v1) & np.isfinite(v2)
    frac = np.minimum(np.maximum((v1 - level) / np.maximum(v1 - v2, 1e-6), 0.0), 1.0)
    r0, dr = radii[jj - 1], radii[jj] - radii[jj - 1]
    slope = (v1 - v2) / np.maximum(dr, 1e-12)
    return r0 + frac * dr, has, slope


def fit_glare(
    grey: np.ndarray,
    lens: FisheyeLens,
    x0: float,
    y0: float,
    r_px: float,
    peak: float,
    opts: GlareOptions = GlareOptions(),
    *,
    up_cam: np.ndarray | None = None,
    radiometry: Radiometry | None = None,
    smear: np.ndarray | None = None,
) -> GlareFit | None:
    """Measure the glare around (x0, y0) (px; a point inside it, ``r_px`` its rough radius).

    Rays are cast on the sphere around the current axis (equal angular steps, projected
    through the lens), starting from the ray through (x0, y0); the sky's asymmetry near the
    rim is removed and the cone refitted, until the axis stops moving (``opts.max_passes``).
    ``up_cam``: the zenith in the camera frame when the orientation is known (samples below
    1 deg elevation are not sky); otherwise samples beyond 88 deg off the optical axis are
    not trusted.  ``radiometry``: the camera's response and vignetting; with it the sky is
    modelled in light, undone of the vignetting, and each ray's rim level turned back into
    grey (:mod:`.radiometry`).  ``smear``: a column smear per column (:mod:`.smear`), taken
    off the samples (unknown where it exceeds the rim's depth under the clip).
    """
    H, W = grey.shape
    xc, yc, r = float(x0), float(y0), max(float(r_px), 1.5)
    # a saturated streak (bloom) costs the rays that run into it (the module's step 2).  The
    # candidate's disk is rough (a noisy plateau's inscribed disk is small and off centre):
    # a streak that leaves one way only is judged around the first pass's rim instead
    streak, axis = (0.0, 1) if opts.column_bloom else streak_along(grey, xc, yc, r, peak - 3)
    if streak:
        streak = None
    dpp = lens.deg_per_px(xc, yc)
    n_rays = int(np.clip(round(2 * math.pi * r / 0.8), opts.min_rays, opts.max_rays))
    phi = np.arange(n_rays) * (2 * math.pi / n_rays)
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)

    # -- start: the ray through the inscribed disk's centre, the disk's angular radius ----
    d0, ok0 = lens.rays([[xc, yc]])
    if not ok0[0]:
        return None
    a = d0[0]
    rho = math.radians(r * dpp)
    floor = math.radians(opts.noise_floor_px * dpp)
    idx = np.zeros(0, int)
    has = np.zeros(n_rays, bool)
    rms = float("inf")
    moved = 0.0
    sky = SkyBehind()  # the last reading of the sky behind the rim (:mod:`.rimsky`)
    alpha, alpha_sd = 0.0, math.inf  # the blend (:mod:`.blend`) and its one-sigma from the rim

    # -- pass 2: rays on the sphere around the axis ---------------------------------------
    step = math.radians(max(opts.step_px, 0.04 * r) * dpp)  # ~25 samples across a radius
    ring_sel = np.arange(0, n_rays, max(1, n_rays // 36))
    lo_f, hi_f = 0.5, 1.7
    reads, settled, unsettled = 0, math.radians(opts.sky_settled_deg), math.radians(opts.sky_unsettled_deg)
    kept_stale = False  # the settled fit's sky was read inside the glare
    for it in range(opts.max_passes):
        e1, e2 = tangent_basis(a)
        dirs_t = cos_phi[:, None] * e1 + sin_phi[:, None] * e2  # the rays' directions at the axis
        geometry = (lens, a, e1, e2, phi, rho)
        # the streak's rays (along the image's columns, or its rows): both ways, those near its
        # axis (by design: not in the rim's gaps); one way, those towards it (counted)
        streak_ok, rays_ok = streak_rays(geometry, streak, axis)
        rim_chi = np.arange(lo_f * rho, hi_f * rho, step)
        if rim_chi.size < 2:  # a step wider than the rim (a fit shrunk far inside the candidate)
            return None
        # the sky behind the rim, read around the current axis on the first two passes and
        # again once the axis has settled (see GlareOptions.sky_reads)
        sky_pass = it < 2 or (reads < opts.sky_reads and moved < settled)
        reads += int(sky_pass)
        if sky_pass and it >= 2:  # a settled fit, kept in case the new reading unsettles it
            kept = (a, rho, sky)
            kept_stale = sky.inside and opts.drop_stale_sky
        grids = [(phi, rim_chi)]
        if sky_pass:
            ring_chi = np.arange(1.15 * rho, 3.2 * rho + 4 * step, 3 * step)
            grids.append((phi[ring_sel], ring_chi))
        sm = None if smear is None else (smear, peak - CLIP_MARGIN, (1.0 - opts.level) * (peak - sky.bg))
        samples = sample_sphere(grey, lens, a, e1, e2, up_cam, grids, sm)
        vals = np.where(samples[0][1], samples[0][0], np.nan)  # no rim below the horizon
        if sky_pass:
            read = read_sky(
                samples[1],
                ring_chi,
                (lens, a, e1, e2, phi[ring_sel], rho),
                rays_ok[ring_sel],
                None if up_cam is None else dirs_t[ring_sel] @ up_cam,
                peak,
                opts,
                sky,
                first=it == 0,
                streak_free=streak is None,
                alpha=alpha,
                dpp=dpp,
                up_cam=up_cam,
                radiometry=radiometry,
            )
            if read is None:
                return None
            sky = read
        dirs_up = None if up_cam is None else dirs_t @ up_cam
        level, shift, shift_s = rim_levels(sky, geometry, dirs_up, peak, opts, up_cam, radiometry)
        chi_c, has, slope = _crossings(vals, rim_chi, level)
        has &= rays_ok & (level < sky.bg + 0.95 * (peak - sky.bg))  # a sky this bright hides the rim
        if sky.by_el is not None:  # near the horizon the sky model extrapolates: a large
            has &= np.abs(shift_s) <= opts.max_horizon_shift * (sky.top_s - sky.bg_s)  # shift is a guess
        if dirs_up is not None:  # the last degrees above the horizon change too fast to model
            sin_rim = np.cos(chi_c) * float(a @ up_cam) + np.sin(chi_c) * dirs_up
            has &= sin_rim > _SIN_RIM_MIN
        if has.sum() < 8:
            return None
        pts = np.cos(chi_c)[:, None] * a + np.sin(chi_c)[:, None] * dirs_t
        a_new, rho, inl, rms, blend = _fit_rim(lens, pts[has], opts, floor, dpp, alpha if it else None)
        if blend is not None:
            alpha, alpha_sd = blend
        if not (math.isfinite(rho) and 0.0 < rho < _RHO_MAX):
            return None  # not a small circle: the edge of a flat patch, fitted as a vast or inverted one
        idx = np.flatnonzero(has)[inl]
        moved = math.acos(min(1.0, float(a_new @ a)))
        a = a_new
        if sky_pass and it >= 2 and moved > unsettled and not kept_stale:
            # a reading that moves a settled axis this far is a cloud's, not a correction of
            # the linearisation: back to the settled fit and its sky, no more readings, and
            # one more pass to refit the rim there (on the last pass, the fit is left unsettled)
            a, rho, sky = kept
            reads = opts.sky_reads
        lo_f, hi_f = 0.7, 1.45  # the rim is known now: sample around it only
        if it == 0 and streak is None and opts.one_way_streaks:
            uv0, ok0 = lens.project(a[None, :])
            if ok0[0]:
                streak, axis = streak_along_at_core(grey, float(uv0[0, 0]), float(uv0[0, 1]), peak - 3)
        # settled: done, once the sky has been read around this axis (or read enough)
        if it >= 1 and moved < 0.5 * floor and (sky_pass or reads >= opts.sky_reads):
            break
    flags = ["sky_dipole"] if float(np.linalg.norm(sky.dipole)) > 2.0 else []
    flags += ["sky_by_elevation"] if sky.by_el is not None else []
    # how far the sky's correction moved the rim's centre: its error is a share of it
    sky_move = sky_harmonic = 0.0
    if idx.size >= 3:
        moves = -np.asarray(shift * np.ones(n_rays))[idx] / np.maximum(slope[idx], 1e-9)
        sky_move, sky_harmonic = centre_move(moves, cos_phi[idx], sin_phi[idx])
    if alpha >= 0.75:
        flags.append("round_in_image")
    uv, okp = lens.project(a[None, :])
    if not okp[0]:
        return None
    xc, yc = float(uv[0, 0]), float(uv[0, 1])
    if not (0 <= xc < W and 0 <= yc < H):
        return None
    r_fit = max(math.degrees(rho) / dpp, 1.0)
    gap_deg, gap_rays = _largest_gap(idx, streak_ok)
    kept_rays = np.zeros(n_rays, bool)
    kept_rays[idx] = True
    short_bloom = streak is None and short_bloom_both_ways(geometry, chi_c, has, kept_rays)
    # a one-sided streak's rays are in the gap (its rim is unseen there) but found no rim by
    # design: the sky's gap is judged on the gap's other rays
    sky_rays = gap_rays[rays_ok[gap_rays]]
    # the sky's gap faces the horizon; near it, where the sky is modelled by elevation and
    # the model's guesses at the rim's top and bottom are dropped, it may face the zenith too
    mid = float(phi[gap_rays[gap_rays.size // 2]]) if gap_rays.size else 0.0
    faces_sky = faces_horizon(mid, a, e1, e2, up_cam) or (
        sky.by_el is not None and faces_horizon(mid + math.pi, a, e1, e2, up_cam)
    )
    return GlareFit(
        axis=a,
        radius_deg=math.degrees(rho),
        rms_deg=math.degrees(rms),
        n_rays=int(streak_ok.sum()),
        n_valid=int(has.sum()),
        n_inliers=len(idx),
        max_gap_deg=gap_deg,
        sky_gap=sky_rays.size > 0 and faces_sky and float(np.mean(has[sky_rays])) < 0.5,
        centre_uv=(xc, yc),
        radius_px=r_fit,
        peak=peak,
        background=sky.bg,
        core_fill=core_fill(grey, (xc, yc), r_fit, sky.bg + opts.level * (peak - sky.bg)),
        deg_per_px=dpp,
        smear=None if streak is None else "bloom",
        one_way_streak=bool(streak),
        short_bloom=short_bloom,
        flags=flags,
        image_share=alpha,
        image_share_sigma=alpha_sd,
        last_move_deg=math.degrees(moved),
        sky_move_deg=math.degrees(sky_move),
        sky_harmonic_deg=math.degrees(sky_harmonic),
        sky_reading=sky.reading,
    )


def _fit_rim(
    lens: FisheyeLens, pts: np.ndarray, opts: GlareOptions, floor: float, dpp: float, alpha: float | None
) -> tuple[np.ndarray, float, np.ndarray, float, tuple[float, float] | None]:
    """The rim points ``pts`` (unit vectors, camera frame) fitted: a small circle on the
    sphere (:func:`.sphere.fit_cone`, residuals under ``floor`` rad not told apart), then
    read as a circle in a blend of the sky's and the sensor's metrics (:mod:`.blend`) from
    the cone's inliers and from every point, starting from the blend ``alpha`` (None: the
    prior's, on the first pass).  (axis, radius rad, inliers, RMS rad, the blend and its
    one-sigma or None when the blend was not fitted)."""
    a, rho, inl, rms, _ = fit_cone(pts, k=opts.outlier_k, floor_rad=floor)
    uv, ok = lens.project(pts)
    if not ok.all():
        return a, rho, inl, rms, None
    bf = fit_blend(
        lens,
        pts,
        uv,
        a,
        [inl, np.ones(len(inl), bool)],
        k=opts.outlier_k,
        floor_rad=floor,
        alpha0=opts.blend_prior[0] if alpha is None else alpha,
        scale_rad=math.radians(dpp),
        prior=opts.blend_prior,
    )
    if bf is None:
        return a, rho, inl, rms, None
    return bf.axis, bf.rho, bf.inliers, bf.rms, (bf.alpha, bf.alpha_sigma)


def _largest_gap(idx: np.ndarray, usable: np.ndarray) -> tuple[float, np.ndarray]:
    """Largest run (deg) of usable rays without an inlier, around the circle, and those
    rays, in order.  Rays that could not be used by design (those a bloom streak covers)
    are skipped, not counted: the streak's sectors are known and symmetric, a cloud's are
    not."""
    rays = np.flatnonzero(usable)  # the usable rays, in order around the circle
    m = rays.size
    pos = np.cumsum(usable) - 1  # each usable ray's rank among the usable ones
    idx = idx[usable[idx]]
    if idx.size == 0 or m == 0:
        return 360.0, rays
    s = np.sort(pos[idx])
    gaps = np.diff(np.concatenate([s, [s[0] + m]]))
    k = int(np.argmax(gaps))
    return float((gaps[k] - 1) * 360.0 / m), rays[(s[k] + 1 + np.arange(gaps[k] - 1)) % m]
