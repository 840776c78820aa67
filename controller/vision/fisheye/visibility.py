"""Whether a fitted glare is the sun (the visibility rules), and how well it places it.

The default pipeline's step 3 (:mod:`.default`; docs/fisheye.md has the reasoning and the
measured figures): a candidate is the sun only if its glare is round on the sphere (rim
RMS), complete (inliers all round it), of a plausible angular size, stands out from the
sky, has a full core, was not placed by the sky's model of its rim more than by the rim,
and (orientation known) is above the horizon (:func:`judge`); the sun it places has a
one-sigma built from the rim's own figures (:func:`glare_sigma`).  :class:`FisheyeOptions`
holds those thresholds with the pipeline's other options.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .gates import GateOptions
from .glare import GlareFit, GlareOptions

#: Order in which a refused frame's reason is reported when candidates failed differently.
REASON_ORDER = tuple(
    "lens_ghost static_glare glare_shrunk below_horizon irregular_glare incomplete_glare"
    " sky_dominated low_contrast glare_too_small glare_too_large no_rim".split()
)


@dataclass(frozen=True)
class FisheyeOptions:
    """Decision thresholds of the default pipeline (angles in degrees).

    All are physical or geometric (angular sizes, fractions of the rim), none in pixels of
    one particular camera except ``max_rms_px``, the rim's roughness relative to the pixel (a
    cloud-mangled sun's rim is rough by a few per cent of its radius, a saturated cloud patch
    by tens of per cent; our broken-cloud suite's visible suns: median 0.07 px and 0.6 %, p95
    0.20 px and 1.8 %; a thin cloud's bright halo around a dimmed sun, fitted 1-5 deg off it,
    4 % in the median: the third renderer's clouds without the site gave 45 such detections
    with 0.6 px + 8 %, 25 with 0.3 px + 4 %; 0.3 px + 3 % cost our suite a miss and, without
    the site, a false detection; docs/fisheye.md step 8), and ``small_glare_px``: a glare a few
    pixels in radius must show ``small_min_inlier_fraction`` of its rim (a rim of a few pixels
    on part of its rays is a sunlit cloud's fleck: 35-71 % of their rays on both renderers'
    broken-cloud suites; suns dimmed by thin cloud 83-100 % and 56-92 %).
    A rim whose largest gap is the sky's (most of its rays found no rim, and it faces the
    horizon, its middle within 60 deg of down the vertical through the glare, or near the
    horizon the zenith: the clear sky brightens towards the horizon until the rays clip, or
    the sky's model is a guess) may miss ``max_horizon_gap_deg`` at most: the arc left
    carries that model's error on its radius straight into its centre (second renderer,
    wide glare, 15-19 deg: 0.15-0.70 deg off with 100-113 deg gaps; 83-97 deg gaps within
    0.05).  A cloud's gap is of rays whose rims it pulled in (outliers): ``max_gap_deg``.
    A glare whose centre the sky's correction of its rim moved more than ``max_sky_move_deg``
    (its first harmonic on the rays, as measured; sigma takes the fitted move, :mod:`.sphere`)
    is refused (``sky_dominated``): that centre is the sky model's, good to 5-15 % (a 1-deg
    move: 0.05-0.15 deg). On 12 clear looks of both renderers the 9 frames that moved 1.1-1.6
    deg read 0.08-0.21 deg off (a hard-edged disk in a bright sky at 18-19 deg, both sizes; CIE
    sky 15 clipping about a sun at 27 deg); the 26 that moved 0.6-0.96 deg, within 0.11.
    A sun whose own sigma exceeds ``max_sigma_deg`` is refused (``imprecise_glare``): no gate or
    loop can use it, and a wrong one that size is what it stands for (a rim held on 35 % of its
    rays at 14.5 deg, sigma 1.8, 0.89 off; our bright sky at 22-24 deg, sigma 1.2-1.3, 0.10-0.14
    off).  Under ``near_horizon_deg`` the bound is ``max_sigma_near_horizon_deg``: there the
    error is the elevation model's, the same way frame after frame (CIE sky type 10 at 5-10
    deg: sigma 0.53-0.90, all read 0.09-0.42 high), which a filter takes for noise.
    """

    glare: GlareOptions = field(default_factory=GlareOptions)
    gates: GateOptions = field(default_factory=GateOptions)
    min_peak: float = 200.0  # grey level: below it nothing is saturated
    sat_margin: float = 4.0  # grey levels under the peak that count as saturated
    min_radius_deg: float = 0.8  # the sun's disk is 0.27 deg; smaller: a point source, or too dim
    max_radius_deg: float = 20.0
    min_inlier_fraction: float = 0.35
    small_glare_px: float = 4.0  # a glare this small (radius) must show nearly all its rim
    small_min_inlier_fraction: float = 0.8
    max_gap_deg: float = 150.0  # largest arc of the rim without an inlier
    max_horizon_gap_deg: float = 100.0  # ... when that arc faces the horizon
    max_rms_px: float = 0.3  # rim residual RMS: this many pixels at the glare ...
    max_rms_rel: float = 0.04  # ... plus this fraction of its radius
    min_core_fill: float = 0.9
    max_last_move_deg: float = 0.1  # a fit still moving this much at its last pass: unsettled
    max_sigma_deg: float = 1.0  # a sun placed no better than this is no observation
    max_sigma_near_horizon_deg: float = 0.5  # the same under near_horizon_deg (see above)
    max_sky_move_deg: float = 1.0  # the sky's correction moved the centre further: the sky's, not the glare's
    min_contrast: float = 0.12  # (peak - sky) / peak
    horizon_margin_deg: float = 1.0
    ambiguity_ratio: float = 1.25  # the sun's glare must be this much larger
    ghost_align_deg: float = 2.0  # a smaller glare this close to opposite a larger one: its ghost
    max_blobs: int = 6
    sigma_floor_deg: float = 0.015
    sky_sigma_share: float = 0.5  # the sky's correction of the rim is trusted to half its size
    near_horizon_deg: float = 12.0


@dataclass
class Candidate:
    """A glare fitted and judged: its rim, its direction in the camera frame and in ENU (None
    without the orientation), its elevation (deg), and why it is not the sun (None: it may be)."""

    fit: GlareFit
    d_cam: np.ndarray
    d_enu: np.ndarray | None
    el_deg: float | None
    reason: str | None


def judge(fit: GlareFit, o: FisheyeOptions, R: np.ndarray | None) -> Candidate:
    """``fit`` judged by the visibility rules of ``o`` (:class:`FisheyeOptions`): a
    :class:`Candidate` whose ``reason`` is None when the glare may be the sun, else why not
    (:data:`REASON_ORDER`); ``R``: ENU from camera (None: the orientation is unknown, no
    elevation)."""
    d_cam = fit.axis
    d_enu = R @ d_cam if R is not None else None
    el = float(math.degrees(math.asin(np.clip(d_enu[2], -1, 1)))) if d_enu is not None else None
    reason = None
    if (
        fit.rms_deg > o.max_rms_px * fit.deg_per_px + o.max_rms_rel * fit.radius_deg
        or fit.core_fill < o.min_core_fill
        or fit.last_move_deg > o.max_last_move_deg
    ):
        reason = "irregular_glare"
    elif (
        fit.inlier_fraction < o.min_inlier_fraction
        or fit.max_gap_deg > o.max_gap_deg
        or (fit.sky_gap and fit.max_gap_deg > o.max_horizon_gap_deg)
        or (fit.radius_px < o.small_glare_px and fit.inlier_fraction < o.small_min_inlier_fraction)
    ):
        reason = "incomplete_glare"
    elif fit.sky_harmonic_deg > o.max_sky_move_deg:
        reason = "sky_dominated"
    elif fit.contrast < o.min_contrast:
        reason = "low_contrast"
    elif fit.radius_deg < o.min_radius_deg:
        reason = "glare_too_small"
    elif fit.radius_deg > o.max_radius_deg:
        reason = "glare_too_large"
    elif el is not None and el < -o.horizon_margin_deg:
        reason = "below_horizon"
    return Candidate(fit, d_cam, d_enu, el, reason)


def glare_sigma(f: GlareFit, o: FisheyeOptions, sigma_cal: float) -> float:
    """The one-sigma (deg) of the sun placed by the rim ``f``: its scatter over its rays, a
    share of its roughness and of the rim it lost, the floor ``o.sigma_floor_deg``, the
    camera's calibration ``sigma_cal`` (deg), the last pass's step and a share
    (``o.sky_sigma_share``) of how far the sky's correction moved its centre."""
    sig_fit = f.rms_deg * math.sqrt(2.0 / max(f.n_inliers, 3))
    # a rim bent by a cloud nearby, or partly lost to one, moves the centre by a share of
    # the bending and of the radius: systematic, not averaged down by the rays
    sig_rim = 0.5 * f.rms_deg
    sig_partial = 0.5 * f.radius_deg * (1.0 - f.inlier_fraction) ** 2
    # a fit still moving at its last pass has not settled: its step is part of the error;
    # so is a share of how far the sky's correction moved the centre (a sky that
    # brightens steeply around a low sun is modelled only in part)
    sigma = math.sqrt(
        sig_fit**2
        + sig_rim**2
        + o.sigma_floor_deg**2
        + sigma_cal**2
        + sig_partial**2
        + f.last_move_deg**2
        + (o.sky_sigma_share * f.sky_move_deg) ** 2
    )
    return sigma
