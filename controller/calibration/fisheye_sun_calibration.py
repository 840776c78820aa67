"""The sky camera calibrated from a day of its own sun detections: rotation, then the
sky-correction scale with it (``heliotrack calibrate fisheye orientation``).

1. The frames are measured in the camera frame (no orientation, so no gate by ENU) and the
   rotation fitted to pvlib's sun (:func:`.fisheye_orientation.fit_orientation`).
2. The locator.  With the site known, a camera whose sky is a product places its sun by the
   sky's rings (:mod:`controller.vision.fisheye.rings`), and a rotation fitted to the rim's
   fixes carries the rim's bias into every fix.  With step 1's rotation, the frames are
   measured by the rim and by the rings wherever they place the sun; each locator's fixes on
   the frames both placed get their own rotation.  When the rings' residual squared is under
   :data:`RINGS_LEAD` times the rim's (the share by which the camera's
   :class:`~controller.vision.fisheye.locator.LocatorChoice` picks them at run time), the
   rings' rotation, fitted on all their fixes, is the calibration, with the sky as handed
   over: the rings read its product themselves, and the steps below scale the rim's
   correction, which they do not use.  The rim is compared as handed over, not as steps 3-5
   would scale it: those scales are fitted on the same frames (up to five parameters more),
   and on a product sky their fit of one day did not hold on the next (the third renderer
   at 1280 x 960, calibrated on 20 Mar: 0.015 deg on its own day, 0.046 on the others).
   The choice is written to the bundle (``[orientation] locator``): the camera starts with it.
3. Otherwise, with that rotation (the vertical known, so a low sun's sky is modelled by
   elevation, as in use), the frames are measured again with the sky's correction as it is
   and scaled by ``1 + SCALE_STEP``; :func:`.fisheye_sky_scale.fit_sky_scale` fits the scale
   and the rotation together.
4. The frames are measured twice more, their column smear taken off (a frame-transfer
   CCD's; :mod:`controller.vision.fisheye.smear`), and a scale for each sky model, linear
   in the air mass, is fitted with the rotation
   (:func:`.fisheye_sky_scale.fit_sky_calibration`), scored against what step 3 adopted.
5. When the scale or the calibration earns its place, the frames are measured a last time
   with it and the rotation fitted (and refined) on those detections.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..sun.source import Site
from ..vision.fisheye.locator import LEAD
from .fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3
from .fisheye_orientation import OrientationFit, fit_orientation
from .fisheye_sky_scale import SkyCalibrationFit, SkyScaleFit, fit_sky_calibration, fit_sky_scale

#: the step between the two scales the frames are measured at
SCALE_STEP = 0.25
#: the rings are the calibration's locator when their residual squared is under this share of
#: the rim's (step 2; the run-time choice's :data:`controller.vision.fisheye.locator.LEAD`)
RINGS_LEAD = LEAD
#: ... over at least this many frames that both placed
MIN_BOTH = 12


@dataclass(frozen=True)
class LocatorFit:
    """The rim's and the rings' fixes of a calibration day on the ``frames`` both placed, each
    with its own rotation: the fits' residuals (deg; RMS over each fit's inliers), and the
    locator chosen (step 2 of the module's docstring)."""

    rim_residual_deg: float
    rings_residual_deg: float
    frames: int
    locator: Literal["rim", "rings"]


@dataclass
class SunCalibration:
    """Result of :func:`calibrate_from_sun`."""

    bundle: FisheyeBundle  # the input bundle with [orientation] (and [site], the lens) set
    fit: OrientationFit  # the last rotation fit
    sky: SkyScaleFit | None  # None when not fitted (``fit_scale=False``, too few detections)
    detections: int  # frames found in the first pass
    not_found: int
    calibration: SkyCalibrationFit | None = None  # the sky models' scales (None: not fitted)
    locator: LocatorFit | None = None  # the rim against the rings (None: too few frames)


def _detect(
    bundle: FisheyeBundle,
    frames: Sequence[tuple[float, Any]],
    sky_scale: float = 1.0,
    smear: bool = False,
    rings: bool = False,
) -> list:
    """(t, d_cam, centre_uv, sky modelled by elevation) per frame, None where not found;
    ``frames``: (POSIX s, a BGR image or a path); ``smear``: the column smear taken off.
    The rim's fixes; with ``rings``, the rings' wherever they place the sun, None elsewhere."""
    from ..vision.fisheye import FisheyeEstimator, FisheyeOptions

    opts = FisheyeOptions()
    glare = replace(opts.glare, sky_scale=sky_scale, column_smear=smear or opts.glare.column_smear)
    # a weak rim behind a wide sequence gate is kept (the gate widens over the day's 20-30 min
    # steps): the rotation's fit refuses its own outliers, and these frames inform it (the
    # second renderer's linear output calibrated 0.0204 deg with them, 0.0225 without)
    gates = replace(opts.gates, ring_locator=rings, rings_always=rings, sequence_vouch_max_deg=math.inf)
    est = FisheyeEstimator(bundle, replace(opts, glare=glare, gates=gates))
    out: list = []
    for t, frame in frames:
        r = est.estimate_file(frame, t) if isinstance(frame, (str, Path)) else est.estimate_image(frame, t)
        ok = r.found and r.d_cam is not None and r.centre_uv is not None
        ok = ok and (not rings or "ring_locator" in r.quality)
        by_el = "sky_by_elevation" in r.quality
        out.append((t, np.asarray(r.d_cam, float), np.asarray(r.centre_uv, float), by_el) if ok else None)
    return out


def _pairs(a: list, b: list) -> list:
    return [(x, y) for x, y in zip(a, b) if x is not None and y is not None]


def _columns(pairs: list) -> tuple[list[float], np.ndarray, np.ndarray]:
    """The times, and the directions found at the two scales, of :func:`_pairs`' frames."""
    return [a[0] for a, _ in pairs], np.array([a[1] for a, _ in pairs]), np.array([b[1] for _, b in pairs])


def _fit(found: list, site: Site, bundle: FisheyeBundle, **kw) -> OrientationFit:
    return fit_orientation(
        [f[0] for f in found],
        np.array([f[1] for f in found]).reshape(-1, 3),
        site,
        uv=np.array([f[2] for f in found]).reshape(-1, 2),
        camera=bundle.camera,
        **kw,
    )


def _by_rings(
    bundle: FisheyeBundle, frames: Sequence[tuple[float, Any]], site: Site, **kw
) -> tuple[LocatorFit, OrientationFit | None] | None:
    """The rim against the rings on ``bundle`` (step 1's rotation, the site): the comparison,
    and the rings' rotation when they lead (step 2 of the module's docstring); None when
    fewer than :data:`MIN_BOTH` frames were placed by both."""
    rim, rings = _detect(bundle, frames), _detect(bundle, frames, rings=True)
    both = [(a, b) for a, b in zip(rim, rings) if a is not None and b is not None]
    if len(both) < MIN_BOTH:
        return None
    res_rim = _fit([a for a, _ in both], site, bundle, **kw).residual_deg
    res_rings = _fit([b for _, b in both], site, bundle, **kw).residual_deg
    lead = res_rings**2 < RINGS_LEAD * res_rim**2
    choice = LocatorFit(res_rim, res_rings, len(both), "rings" if lead else "rim")
    return choice, _fit([f for f in rings if f is not None], site, bundle, **kw) if lead else None


def _rounded(k: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    return (round(k[0], 4), round(k[1], 4), round(k[2], 4), round(k[3], 4))


def _with_fit(
    bundle: FisheyeBundle,
    fit: OrientationFit,
    site: SiteCal,
    method: str,
    scale: float,
    calibration: tuple[float, float, float, float] | None = None,
) -> FisheyeBundle:
    new = replace(
        bundle,
        orientation=OrientationCal(
            enu_from_camera=as_mat3(fit.enu_from_camera),
            residual_deg=round(fit.residual_deg, 5),
            method=method,
            frames=fit.used,
            sky_scale=round(scale, 4),
            sky_calibration=None if calibration is None else _rounded(calibration),
        ),
        site=site,
    )
    return replace(new, camera=fit.camera) if fit.camera is not None else new


def calibrate_from_sun(
    bundle: FisheyeBundle,
    frames: Sequence[tuple[float, Any]],
    site: SiteCal,
    *,
    refine: str | None = "rotation",
    horizon_zenith_cam: np.ndarray | None = None,
    fit_scale: bool = True,
) -> SunCalibration:
    """Rotation (and sky-correction scale) from a day of frames at ``site``.

    ``frames``: (POSIX s, BGR image or path), a clear day's worth (the sun over a wide arc).
    ``refine`` and ``horizon_zenith_cam``: as for :func:`.fisheye_orientation.fit_orientation`.
    """
    sun_site = Site(latitude=site.latitude, longitude=site.longitude, altitude=site.altitude)
    kw = {"refine": refine, "horizon_zenith_cam": horizon_zenith_cam}
    method = "sun" + ("+horizon" if horizon_zenith_cam is not None else "")
    first = _detect(replace(bundle, orientation=None), frames)
    found = [f for f in first if f is not None]
    fit = _fit(found, sun_site, bundle, **kw)
    lens = "+lens" if fit.camera else ""
    out = _with_fit(bundle, fit, site, method + lens, 1.0)
    sky: SkyScaleFit | None = None
    cal: SkyCalibrationFit | None = None
    locator = _by_rings(out, frames, sun_site, **kw)
    choice = None if locator is None else locator[0]
    if locator is not None and locator[1] is not None:
        fit = locator[1]
        out = _with_fit(out, fit, site, method + lens + "+rings", 1.0)
    elif fit_scale:
        pairs = _pairs(_detect(out, frames), _detect(out, frames, 1.0 + SCALE_STEP))
        if len(pairs) >= 12:
            sky = fit_sky_scale(*_columns(pairs), SCALE_STEP, sun_site)
            beat = sky.residual_deg if sky.scale != 1.0 else sky.residual_unscaled_deg
            pairs = _pairs(_detect(out, frames, smear=True), _detect(out, frames, 1.0 + SCALE_STEP, True))
            if len(pairs) >= 12:
                by_el = [a[3] for a, _ in pairs]
                cal = fit_sky_calibration(
                    *_columns(pairs), SCALE_STEP, by_el, sun_site, beat, scale=sky.scale
                )
        if cal is not None and cal.adopted:
            ori = OrientationCal(
                enu_from_camera=as_mat3(cal.enu_from_camera), sky_calibration=cal.coefficients
            )
            last = [f for f in _detect(replace(out, orientation=ori), frames) if f is not None]
            fit = _fit(last, sun_site, bundle, **kw)  # the lens's priors: the boards' values
            out = _with_fit(out, fit, site, method + lens + "+sky_calibration", 1.0, cal.coefficients)
        elif sky is not None and sky.scale != 1.0:
            # the fitted rotation replaces the first one's: the last pass is gated by it
            ori = OrientationCal(enu_from_camera=as_mat3(sky.enu_from_camera))
            at = replace(out, orientation=ori)
            last = [f for f in _detect(at, frames, sky.scale) if f is not None]
            fit = _fit(last, sun_site, bundle, **kw)  # the lens's priors: the boards' values
            out = _with_fit(out, fit, site, method + lens + "+sky_scale", sky.scale)
    if choice is not None:  # the camera starts with it (and goes on learning: .locator.LocatorChoice)
        assert out.orientation is not None
        out = replace(out, orientation=replace(out.orientation, locator=choice.locator))
    return SunCalibration(out, fit, sky, len(found), len(first) - len(found), cal, choice)
