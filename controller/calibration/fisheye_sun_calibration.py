"""The sky camera calibrated from a day of its own sun detections: rotation, then the
sky-correction scale with it (``heliotrack calibrate fisheye orientation``).

1. The frames are measured in the camera frame (no orientation, so no gate by ENU) and the
   rotation fitted to pvlib's sun (:func:`.fisheye_orientation.fit_orientation`).
2. With that rotation (the vertical known, so a low sun's sky is modelled by elevation, as
   in use), the frames are measured again with the sky's correction as it is and scaled by
   ``1 + SCALE_STEP``; :func:`.fisheye_sky_scale.fit_sky_scale` fits the scale and the
   rotation together.
3. The frames are measured twice more, their column smear taken off (a frame-transfer
   CCD's; :mod:`controller.vision.fisheye.smear`), and a scale for each sky model, linear
   in the air mass, is fitted with the rotation
   (:func:`.fisheye_sky_scale.fit_sky_calibration`), scored against what step 2 adopted.
4. When the scale or the calibration earns its place, the frames are measured a last time
   with it and the rotation fitted (and refined) on those detections.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..sun.source import Site
from .fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3
from .fisheye_orientation import OrientationFit, fit_orientation
from .fisheye_sky_scale import SkyCalibrationFit, SkyScaleFit, fit_sky_calibration, fit_sky_scale

#: the step between the two scales the frames are measured at
SCALE_STEP = 0.25


@dataclass
class SunCalibration:
    """Result of :func:`calibrate_from_sun`."""

    bundle: FisheyeBundle  # the input bundle with [orientation] (and [site], the lens) set
    fit: OrientationFit  # the last rotation fit
    sky: SkyScaleFit | None  # None when not fitted (``fit_scale=False``, too few detections)
    detections: int  # frames found in the first pass
    not_found: int
    calibration: SkyCalibrationFit | None = None  # the sky models' scales (None: not fitted)


def _detect(
    bundle: FisheyeBundle, frames: Sequence[tuple[float, Any]], sky_scale: float = 1.0, smear: bool = False
) -> list:
    """(t, d_cam, centre_uv, sky modelled by elevation) per frame, None where not found;
    ``frames``: (POSIX s, a BGR image or a path); ``smear``: the column smear taken off."""
    from ..vision.fisheye import FisheyeEstimator, FisheyeOptions

    opts = FisheyeOptions()
    glare = replace(opts.glare, sky_scale=sky_scale, column_smear=smear or opts.glare.column_smear)
    # the rim's fixes: it is the rim that the rotation and the sky's scales are fitted to (at
    # run time a camera with the site may place the sun by its rings: .vision.fisheye.rings)
    gates = replace(opts.gates, ring_locator=False)
    est = FisheyeEstimator(bundle, replace(opts, glare=glare, gates=gates))
    out: list = []
    for t, frame in frames:
        r = est.estimate_file(frame, t) if isinstance(frame, (str, Path)) else est.estimate_image(frame, t)
        ok = r.found and r.d_cam is not None and r.centre_uv is not None
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
    if fit_scale:
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
    return SunCalibration(out, fit, sky, len(found), len(first) - len(found), cal)
