"""Radiometric calibration of the fisheye sky camera: the response (grey level -> light)
from bracketed frames of a still scene, and the lens's relative illumination (vignetting)
from flat fields.  Both feed the bundle's ``[radiometry]``
(:class:`~controller.calibration.fisheye_bundle.RadiometryCal`); the CLI is
``heliotrack calibrate fisheye response|vignetting`` (docs/fisheye-radiometry-calibration.md).

**Response.**  Debevec & Malik's least squares (SIGGRAPH 1997): with ``g = ln(light)`` at each
grey level ``z`` and ``E_i`` the (unknown) light at sample ``i``, every unclipped observation
says ``g(z_ij) = ln E_i + ln t_j``; a smoothness prior fills in what the data leave open.  It
is solved here rather than by ``cv2.createCalibrateDebevec`` or ``Robertson``, which were
measured first on the same synthetic brackets (tests/controller/calibration/
test_fisheye_radiometry.py; max error of the curve normalised at grey 255, over grey
20..235) and came out worse:

* OpenCV keeps every sample in every frame, clipped ones included (weight 1 at grey 0 and
  255), and with noise after the clip a saturated pixel reads 246..255: the top of the curve
  bends up, by 5 to 50 % at grey 255, and normalised there the whole curve is off: Debevec
  0.02..0.5 (samples 70..1000, lambda 10..300), Robertson 0.2..0.5.  Cut at grey 220 and
  extrapolated, Debevec still 0.007..0.03 with 1 EV steps, 0.01..0.06 with 2 EV.
* Here observations at or below :data:`RESPONSE_LO` and at or above :data:`RESPONSE_HI` are
  left out (dark, or clipped under noise), and an outlier pass drops what does not fit (a
  cloud that moved between frames: 0.006..0.017 without it, 0.004 with it).
* With every exposure step equal (ratio ``r``), ``g + p(g)`` for any ``p`` of period
  ``ln r`` fits the data equally (Grossberg & Nayar 2003); the prior decides.  It penalises
  the curvature of ``ln(light)`` against ``ln(grey)``, zero for any power law (linear,
  gamma) and small for sRGB, so what the ambiguity leaves open is pulled to the nearest
  power law.  Measured max error (5 scenes; noise 1 / 2.5 grey levels):

  =========  ===============  ===============  ===============
  camera     1 EV steps       2 EV             3 EV (refused)
  =========  ===============  ===============  ===============
  sRGB       0.0037 / 0.0043  0.0039 / 0.0057  0.0047 / 0.0098
  gamma 2.2  0.0003 / 0.0009  0.0005 / 0.0022  0.0013 / 0.0039
  linear     0.0004 / 0.0015  0.0077 / 0.036   0.025 / 0.13
  =========  ===============  ===============  ===============

  A stronger prior (1e6) halves the linear camera's 2 EV error and doubles sRGB's 1 EV one.
* The three channels share one curve (each pixel and channel has its own light): one fit
  on three times the samples.  It measured the same as the mean of three per-channel
  curves, and better than the green's alone under noise (2 EV, noise 2.5: 0.019 against
  0.023 with an earlier prior).  The pipeline's grey (the mean of the two darkest channels)
  goes through the same curve.

The table's top (above :data:`RESPONSE_HI`) and bottom are the prior's extrapolation, which
follows a power law there; a shoulder in a camera's last 20 grey levels (a filmic S-curve)
is not followed.  Light at grey 0 is 0.

**Vignetting.**  Flat fields (a uniform radiance filling the view) through the calibrated
lens: each pixel's grey (the pipeline's channel, of the frames' mean) turned to light by
the bundle's response, binned by field angle (median per bin), and ``b0 (1 + c1 t^2 +
c2 t^4 + ...)`` fitted by least squares; ``b0`` (the fitted light on the axis) is the
normalisation, so no single noisy bin sets it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from .fisheye_bundle import VIGNETTING_CHECK_DEG, VIGNETTING_MIN, relative_illumination

#: Grey levels (of any channel) at or below which an observation is dark and left out.
RESPONSE_LO = 10
#: Grey levels at or above which an observation may be clipped (noise added after the
#: clip reads a saturated pixel down to ~246) and is left out.
RESPONSE_HI = 235
#: Weight of the smoothness prior, relative to the data's total weight.
RESPONSE_SMOOTHNESS = 3e5
#: Pixels sampled per frame (a regular grid; each gives three channels).
RESPONSE_SAMPLES = 2000
#: The largest ratio between consecutive exposures (a little over 2 EV).
MAX_EXPOSURE_RATIO = 4.5
#: The least ratio between consecutive exposures (distinct exposures).
MIN_EXPOSURE_RATIO = 1.05
#: The usable observations must reach at least this grey level (expose long enough) ...
RESPONSE_NEED_TOP = 200
#: ... and at most this one (short enough).
RESPONSE_NEED_BOTTOM = 40
#: Grey levels (the pipeline's channel) at or above which a flat-field pixel is saturated.
FLAT_SATURATED = 250
#: Grey levels at or below which a flat-field pixel is dark (outside the image circle).
FLAT_DARK = 5
#: Bins need this many pixels.
FLAT_MIN_BIN = 5
#: The first usable bin must start within this field angle (deg), for the normalisation.
FLAT_NEED_AXIS_DEG = 10.0

_OUTLIER_SIGMAS = 5.0


def srgb_response() -> np.ndarray:
    """The sRGB decoding curve (IEC 61966-2-1): relative light (1 at grey 255) at each grey
    level 0..255, shape (256,)."""
    x = np.arange(256.0) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def linear_response() -> np.ndarray:
    """A linear camera: relative light ``grey / 255`` at each grey level, shape (256,)."""
    return np.arange(256.0) / 255.0


def response_deviation(table: Sequence[float] | np.ndarray, reference: np.ndarray) -> float:
    """Max abs difference between two responses, both normalised to 1 at grey 255
    (dimensionless: a fraction of the light at grey 255)."""
    a = np.asarray(table, float)
    b = np.asarray(reference, float)
    return float(np.abs(a / a[-1] - b / b[-1]).max())


def glare_grey(img: np.ndarray) -> np.ndarray:
    """The pipeline's grey (:func:`controller.vision.fisheye.channel.glare_channel`) in
    float: the mean of each pixel's two darkest channels, grey levels 0..255 (a 2-D image
    is its own grey)."""
    a = np.asarray(img, float)
    if a.ndim == 2:
        return a
    return (a.sum(axis=2) - a.max(axis=2)) / 2.0


def _names(n: int, names: Sequence[str] | None) -> list[str]:
    return list(names) if names is not None else [f"frame {i + 1}" for i in range(n)]


def _check_frames(images: Sequence[np.ndarray], names: list[str], what: str, need: int) -> list[np.ndarray]:
    if len(images) < need:
        raise InputError(f"{what}: {len(images)} frame(s), need at least {need}")
    out = []
    for img, name in zip(images, names, strict=True):
        a = np.asarray(img)
        if a.dtype != np.uint8 or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
            raise InputError(f"{name}: expected an 8-bit grey or BGR image, got {a.dtype} {a.shape}")
        if a.shape[:2] != np.asarray(images[0]).shape[:2]:
            h0, w0 = np.asarray(images[0]).shape[:2]
            raise InputError(f"{name}: {a.shape[1]}x{a.shape[0]}, but {names[0]} is {w0}x{h0}")
        a3 = a if a.ndim == 3 else np.repeat(a[:, :, None], 3, axis=2)
        usable = ((a3 > FLAT_DARK) & (a3 < FLAT_SATURATED)).any(axis=2)
        if usable.mean() < 1e-3:
            sat = float((a3 >= FLAT_SATURATED).all(axis=2).mean())
            raise InputError(
                f"{name}: nothing usable, saturated ({100 * sat:.0f} % of the pixels) or black "
                f"(no pixel between grey {FLAT_DARK + 1} and {FLAT_SATURATED - 1})"
            )
        out.append(a3)
    return out


def _smoothness(z0: int = 2) -> np.ndarray:
    """Second differences of ``g`` against ``u = ln(grey)`` at grey levels z0..254, each row
    scaled by the root of its interval (so the sum approximates the integral over ``u``)."""
    u = np.log(np.maximum(np.arange(256.0), 1e-300))
    L = np.zeros((254 - z0 + 1, 256))
    for r, k in enumerate(range(z0, 255)):
        h1, h2 = u[k] - u[k - 1], u[k + 1] - u[k]
        a, c = 2.0 / (h1 * (h1 + h2)), 2.0 / (h2 * (h1 + h2))
        s = math.sqrt((h1 + h2) / 2.0)
        L[r, k - 1], L[r, k], L[r, k + 1] = a * s, -(a + c) * s, c * s
    return L


def _solve_g(
    z: np.ndarray, ii: np.ndarray, lnt: np.ndarray, n: int, smoothness: float, prior: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares for ``g`` (256,) and each sample's ``ln E`` (n,), the samples'
    unknowns eliminated (Schur complement), ``g(128) = 0``."""
    w2 = np.minimum(z, 255 - z).astype(float) ** 2  # Debevec's hat weight, squared
    C = sp.csr_matrix((w2, (z, ii)), shape=(256, n))
    D = np.bincount(ii, w2, n)
    lhs = np.diag(np.bincount(z, w2, 256)) - (C @ sp.diags(1.0 / D) @ C.T).toarray()
    re = np.bincount(ii, w2 * lnt, n)
    rhs = np.bincount(z, w2 * lnt, 256) - C @ (re / D)
    lhs += smoothness * w2.sum() / np.trace(prior) * prior
    lhs[128, 128] += w2.sum()  # the gauge: g(128) = 0
    lhs[0, 0] += 1.0  # g(0): no data, no prior (light 0 is set after)
    g = np.linalg.solve(lhs, rhs)
    lnE = (C.T @ g - re) / D  # = sum w2 (g(z) - ln t) / sum w2, per sample
    return g, lnE


def response_from_brackets(
    images: Sequence[np.ndarray],
    times: Sequence[float],
    *,
    names: Sequence[str] | None = None,
    samples: int = RESPONSE_SAMPLES,
    smoothness: float = RESPONSE_SMOOTHNESS,
) -> np.ndarray:
    """The camera's response from brackets of one still scene.

    Parameters
    ----------
    images
        At least 3 frames of the same still scene, BGR (or grey) uint8, all the same size,
        taken with different exposures (aperture, gain and white balance fixed).
    times
        Exposure time of each frame, seconds (any common scale: only ratios matter), in the
        frames' order; distinct, consecutive ones (sorted) at most
        :data:`MAX_EXPOSURE_RATIO` apart.
    names
        The frames' names for messages (default ``frame 1``, ...).
    samples
        Pixels sampled (a regular grid over the frame).
    smoothness
        Weight of the prior (relative to the data).

    Returns
    -------
    numpy.ndarray
        (256,) relative light at each grey level 0..255: non-decreasing, 0 at grey 0, 1 at
        grey 255 (dimensionless).

    Raises
    ------
    InputError
        Too few frames, sizes that differ, a frame all saturated or all black, missing,
        non-positive or duplicate times, steps over 2 EV, or brackets that do not span the
        grey range (the message names the frame or says what to change).
    """
    nm = _names(len(images), names)
    if len(times) != len(images):
        raise InputError(f"response: {len(times)} exposure time(s) for {len(images)} frame(s)")
    frames = _check_frames(images, nm, "response", 3)
    t = np.asarray(times, float)
    for ti, name in zip(t, nm, strict=True):
        if not (math.isfinite(ti) and ti > 0):
            raise InputError(f"{name}: exposure time must be a positive number of seconds, got {ti}")
    order = np.argsort(t, kind="stable")
    for a, b in zip(order[:-1], order[1:], strict=True):
        ratio = t[b] / t[a]
        if ratio < MIN_EXPOSURE_RATIO:
            raise InputError(
                f"{nm[a]} and {nm[b]}: the same exposure ({t[a]:g} s and {t[b]:g} s); "
                f"exposures must differ by at least {MIN_EXPOSURE_RATIO:g}x"
            )
        if ratio > MAX_EXPOSURE_RATIO:
            raise InputError(
                f"{nm[a]} ({t[a]:g} s) and {nm[b]} ({t[b]:g} s) are {math.log2(ratio):.1f} EV apart: "
                "steps over 2 EV leave the response ambiguous; add frames in between (1 EV steps are best)"
            )
    h, w = frames[0].shape[:2]
    step = max(1, int(round(math.sqrt(h * w / max(1, samples)))))
    # (pixels x channels, frames)
    zs = np.stack([f[step // 2 :: step, step // 2 :: step] for f in frames], axis=-1)
    zs = zs.reshape(-1, len(frames)).astype(np.int64)
    lnt_all = np.log(t)
    valid = (zs > RESPONSE_LO) & (zs < RESPONSE_HI)
    prior = _smoothness()
    prior = prior.T @ prior
    g = None
    for _ in range(2):  # fit, drop outliers (a moving cloud), refit
        keep = valid.sum(axis=1) >= 2
        if keep.sum() < 50:
            raise InputError(
                f"response: only {int(keep.sum())} sampled pixels are unclipped in two or more frames "
                "(need 50): not brackets of one still scene?"
            )
        idx = np.flatnonzero(keep)
        ii, jj = np.nonzero(valid[idx])
        z = zs[idx[ii], jj]
        if z.max() < RESPONSE_NEED_TOP:
            raise InputError(
                f"response: the brackets reach only grey {int(z.max())} unclipped: "
                f"expose longer, so that part of the scene reads {RESPONSE_NEED_TOP}..{RESPONSE_HI - 1}"
            )
        if z.min() > RESPONSE_NEED_BOTTOM:
            raise InputError(
                f"response: nothing darker than grey {int(z.min())}: "
                f"expose shorter, so that part of the scene reads {RESPONSE_LO + 1}..{RESPONSE_NEED_BOTTOM}"
            )
        g, lnE = _solve_g(z, ii, lnt_all[jj], idx.size, smoothness, prior)
        if not np.isfinite(g).all():
            raise InputError("response: the fit did not converge (are these brackets of one scene?)")
        r = g[z] - lnE[ii] - lnt_all[jj]
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        bad = np.abs(r) > max(_OUTLIER_SIGMAS * mad, 0.02)
        if not bad.any():
            break
        valid[idx[ii[bad]], jj[bad]] = False
    assert g is not None
    y = np.exp(g - g.max())
    y[0] = 0.0
    y = np.maximum.accumulate(y)
    return y / y[255]


@dataclass(frozen=True)
class VignettingFit:
    """The lens's relative illumination ``V(t) = 1 + c1 t^2 + c2 t^4 + ...`` fitted to flat
    fields.

    Attributes
    ----------
    coeffs
        ``(c1, c2, ...)`` (``t`` in radians), as the bundle's ``vignetting``.
    rms
        RMS of the fit's residual (relative illumination, dimensionless) over the bins.
    theta_min_deg, theta_max_deg
        Field angles (deg) of the first and last bins used.
    bins
        Number of field-angle bins used.
    pixels
        Number of pixels used.
    """

    coeffs: tuple[float, ...]
    rms: float
    theta_min_deg: float
    theta_max_deg: float
    bins: int
    pixels: int

    def illumination(self, theta_rad: np.ndarray | float) -> np.ndarray:
        """``V`` at field angles ``theta_rad`` (radians)."""
        return relative_illumination(self.coeffs, np.cos(np.asarray(theta_rad, float)))


def vignetting_from_flats(
    images: Sequence[np.ndarray],
    lens,
    radiometry=None,
    *,
    order: int = 3,
    mask: np.ndarray | None = None,
    names: Sequence[str] | None = None,
    bin_deg: float = 0.5,
) -> VignettingFit:
    """The lens's relative illumination from flat-field frames.

    Parameters
    ----------
    images
        At least one frame (the CLI asks for 3) of a uniformly lit target filling the view,
        BGR (or grey) uint8, of the lens's size; their mean is used.
    lens
        The calibrated lens, :class:`controller.vision.fisheye.lens.FisheyeLens` (its
        ``rays`` give each pixel's unit direction; the field angle is ``arccos(z)``).
    radiometry
        The camera's response, :class:`controller.vision.fisheye.radiometry.Radiometry`
        (its vignetting is ignored), or None for a linear camera (light = grey).
    order
        Number of coefficients, 1..4 (``t^2`` .. ``t^8``).
    mask
        Optional (H, W) image, non-zero where the frame may be used (the bundle's mask).
    names
        The frames' names for messages.
    bin_deg
        Width of the field-angle bins, degrees.

    Returns
    -------
    VignettingFit

    Raises
    ------
    InputError
        Sizes that differ from the lens's or each other's, frames all saturated or black,
        nothing usable near the optical axis (saturated: expose shorter), too few bins, or
        a fit that is not a plausible illumination out to 100 deg.

    Notes
    -----
    A pixel is left out if its grey (the mean of its two darkest channels) reaches
    :data:`FLAT_SATURATED` in any frame, or if the mean frame's grey is at most
    :data:`FLAT_DARK` (outside the image circle) or within 2 px of such a pixel or of the
    mask's edge (partly lit).  The light is binned by field angle (median
    per bin, so that noise and a few stray pixels do not bias it) and the bins, weighted
    alike, are fitted by ``b0 (1 + c1 t^2 + ...)``; the coefficients are those divided by
    ``b0``.
    """
    if not 1 <= order <= 4:
        raise InputError(f"vignetting: order must be 1..4, got {order}")
    nm = _names(len(images), names)
    frames = _check_frames(images, nm, "vignetting", 1)
    h, w = frames[0].shape[:2]
    if (w, h) != (lens.width, lens.height):
        raise InputError(f"{nm[0]}: {w}x{h}, but the bundle's camera is {lens.width}x{lens.height}")
    mean = glare_grey(np.mean([f.astype(float) for f in frames], axis=0))
    lit = mean > FLAT_DARK
    if mask is not None:
        m = np.asarray(mask)
        if m.shape[:2] != (h, w):
            raise InputError(f"vignetting: the mask is {m.shape[1]}x{m.shape[0]}, the frames {w}x{h}")
        lit &= (m if m.ndim == 2 else m[:, :, 0]) > 0
    # 2 px off the image circle's edge and the mask's: pixels there are partly lit
    use = cv2.erode(lit.astype(np.uint8), np.ones((5, 5), np.uint8), borderType=cv2.BORDER_REPLICATE) > 0
    for f in frames:
        use &= glare_grey(f) < FLAT_SATURATED
    vs, us = np.nonzero(use)
    if vs.size == 0:
        raise InputError("vignetting: no pixel is neither saturated nor dark in every frame")
    d, ok = lens.rays(np.stack([us, vs], axis=1).astype(float))
    theta = np.degrees(np.arccos(np.clip(d[ok, 2], -1.0, 1.0)))
    grey = mean[vs[ok], us[ok]]
    light = grey if radiometry is None else np.asarray(radiometry.to_light(grey), float)
    b = np.floor(theta / bin_deg).astype(np.int64)
    order_b = np.argsort(b, kind="stable")
    b, light_s, theta_s = b[order_b], light[order_b], theta[order_b]
    starts = np.flatnonzero(np.r_[True, np.diff(b) > 0])
    ends = np.r_[starts[1:], b.size]
    tb, mb = [], []
    for s, e in zip(starts, ends, strict=True):
        if e - s >= FLAT_MIN_BIN:
            tb.append(float(np.median(theta_s[s:e])))
            mb.append(float(np.median(light_s[s:e])))
    if not tb or tb[0] > FLAT_NEED_AXIS_DEG:
        first = f"{tb[0]:.1f} deg" if tb else "nowhere"
        raise InputError(
            f"vignetting: the first usable pixels are at {first} from the optical axis "
            f"(need within {FLAT_NEED_AXIS_DEG:g} deg): saturated? expose shorter"
        )
    if len(tb) < 3 * order:
        raise InputError(f"vignetting: {len(tb)} usable field-angle bins, need {3 * order} for order {order}")
    t = np.radians(np.asarray(tb))
    m = np.asarray(mb)
    A = np.stack([t ** (2 * k) for k in range(order + 1)], axis=1)
    sol, *_ = np.linalg.lstsq(A, m, rcond=None)
    if not np.isfinite(sol).all() or sol[0] <= 0:
        raise InputError("vignetting: the fit failed (is the target lit evenly?)")
    coeffs = tuple(float(c) for c in sol[1:] / sol[0])
    resid = m / sol[0] - relative_illumination(coeffs, np.cos(t))
    fit = VignettingFit(
        coeffs=coeffs,
        rms=float(np.sqrt(np.mean(resid**2))),
        theta_min_deg=float(tb[0]),
        theta_max_deg=float(tb[-1]),
        bins=len(tb),
        pixels=int(ok.sum()),
    )
    th = np.radians(np.linspace(0.0, VIGNETTING_CHECK_DEG, 101))
    v = fit.illumination(th)
    if float(v.min()) < VIGNETTING_MIN or float(v.max()) > 1.0 / VIGNETTING_MIN:
        raise InputError(
            f"vignetting: the fit (to {fit.theta_max_deg:.0f} deg) is not a plausible illumination out to "
            f"{VIGNETTING_CHECK_DEG:g} deg (between {VIGNETTING_MIN} and {1 / VIGNETTING_MIN:g}): "
            "use a lower --order or flat fields that reach further out"
        )
    return fit
