"""Azimuth alignment after levelling: the paper's noon-culmination parabola, and a direct fit
against the ephemeris when site and times are known.  Convention:
az_enu = (az_levelled - offset_deg) mod 360."""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def _unwrap_around(az, ref):
    return (np.asarray(az, float) - ref + 180.0) % 360.0 - 180.0 + ref


#: The largest RMS (deg) of the levelled-minus-ephemeris azimuths about their mean offset.
MAX_SPREAD_DEG = 5.0


#: The noon method refuses a day whose sun goes this far round the horizon: a midnight-sun
#: day has a second extremum, its lowest, that bends the parabola (2.2 deg in an audit), and
#: any cut of it unbalances the fit.
NOON_MAX_SPAN_DEG = 330.0


def _apex_unwrapped(az: np.ndarray, el: np.ndarray) -> tuple[np.ndarray, float]:
    """The azimuths unwrapped about the highest observation's, and that azimuth (deg)."""
    ref = float(az[int(el.argmax())])
    return _unwrap_around(az, ref), ref


def culmination(az_levelled, el_levelled, times) -> str | None:
    """Where the sun culminates, ``"south"`` or ``"north"``, from the sense of its motion.

    Azimuths run clockwise from north, so a sun that culminates in the south moves to
    larger azimuths through its highest point (east, south, west) and one that culminates
    in the north to smaller ones (east, north, west).  That holds at any latitude, the
    tropics included, whatever the azimuth offset; the sun's motion in the 3 h about the
    highest observation decides.  None without times (POSIX s) or with fewer than 3."""
    if times is None:
        return None
    t = np.asarray([np.nan if x is None else x for x in times], float)
    az, el = np.asarray(az_levelled, float), np.asarray(el_levelled, float)
    if t.size < 3 or t.size != az.size or not np.isfinite(t).all():
        return None
    a, _ = _apex_unwrapped(az, el)
    near = np.abs(t - t[int(el.argmax())]) <= 1.5 * 3600.0
    if near.sum() < 3:
        near = np.ones(t.size, bool)
    if np.ptp(t[near]) <= 0:
        return None
    slope = np.polyfit(t[near] - t[near].mean(), a[near], 1)[0]
    return "south" if slope > 0 else "north"


def noon_offset(az_levelled, el_levelled, culminates: str = "south") -> float:
    """Fit el = c0 + c1 az + c2 az^2 to a day; its extremum is the true south (180) or north (0).

    ``culminates``: where the sun's highest point lies (:func:`culmination` tells it from
    the observations' times)."""
    az = np.asarray(az_levelled, float)
    el = np.asarray(el_levelled, float)
    if az.size < 3:
        raise InputError(f"the noon method needs >= 3 observations over a day, got {az.size}")
    a, _ = _apex_unwrapped(az, el)
    if np.ptp(a) > NOON_MAX_SPAN_DEG:
        raise InputError(
            f"the noon method: the observations go {np.ptp(a):.0f} deg round the horizon (a "
            "midnight-sun day), where elevation against azimuth is no parabola; give only the "
            "frames from about 6 h before to 6 h after noon, or use --method ephemeris"
        )
    c2, c1, _ = np.polyfit(a, el, 2)
    if c2 >= 0:
        raise InputError("elevation vs azimuth has no maximum: observations do not span noon")
    apex = -c1 / (2 * c2)
    before, after = int(np.sum(a < apex)), int(np.sum(a > apex))
    if min(before, after) < 2:  # an apex extrapolated from one side of noon (353 deg for 23)
        raise InputError(
            f"the noon method needs observations before and after noon: {before} before and "
            f"{after} after the fitted apex (at least 2 each)"
        )
    true = 180.0 if culminates == "south" else 0.0
    return float((apex - true) % 360.0)


def ephemeris_offset(az_levelled, el_levelled, az_true, el_true=None) -> float:
    """Weighted circular mean of (az_levelled - az_true), weights cos(el).  ``el_true``
    (the ephemeris' elevations, deg), when given, must agree with the levelled ones, which
    the azimuth offset does not touch: a site or a clock half a day off mirrors the sun's
    path into a steady azimuth offset that only the elevations show."""
    if el_true is not None:
        de = np.asarray(el_levelled, float) - np.asarray(el_true, float)
        rms = float(np.sqrt(np.mean(de**2))) if de.size else 0.0
        if not rms <= MAX_SPREAD_DEG:
            raise InputError(
                f"the ephemeris method: the observed elevations and the ephemeris' differ by "
                f"{rms:.1f} deg RMS (at most {MAX_SPREAD_DEG:g}): check --lat/--lon and the times"
            )
    d = np.radians(np.asarray(az_levelled, float) - np.asarray(az_true, float))
    w = np.cos(np.radians(np.asarray(el_levelled, float)))
    if d.size < 1:
        raise InputError("the ephemeris method needs >= 1 observation")
    off = float(np.arctan2((w * np.sin(d)).sum(), (w * np.cos(d)).sum()))
    spread = float(np.degrees(np.sqrt(np.mean(np.angle(np.exp(1j * (d - off))) ** 2))))
    if not spread <= MAX_SPREAD_DEG:  # a wrong site or clock turns the offset with the hour
        raise InputError(
            f"the ephemeris method: the observations and the ephemeris disagree by {spread:.1f} deg "
            f"RMS about one offset (at most {MAX_SPREAD_DEG:g}): check --lat/--lon and the times"
        )
    return float(np.degrees(off) % 360.0)


def ephemeris_rotation(s_model, s_enu, weights=None):
    """Full model -> ENU rotation by a weighted least-squares fit (Wahba / Kabsch) of the
    measured model-frame sun vectors to the ephemeris' ENU vectors.  Returns
    (zenith_model, offset_deg) in the bundle's parametrisation."""
    import cv2

    a = np.asarray(s_model, float)
    b = np.asarray(s_enu, float)
    if a.shape[0] < 2:
        raise InputError("the full ephemeris fit needs >= 2 observations")
    w = np.ones(len(a)) if weights is None else np.asarray(weights, float)
    Hm = (w[:, None] * a).T @ b
    U, _, Vt = np.linalg.svd(Hm)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T  # v_enu = R v_model
    zen = R.T @ np.array([0.0, 0.0, 1.0])
    # offset: az_enu = az_levelled - offset with the levelling rotation of the estimator
    z = zen / np.linalg.norm(zen)
    k = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, k)
    s = np.linalg.norm(axis)
    L = np.eye(3) if s < 1e-15 else cv2.Rodrigues(axis / s * np.arctan2(s, z @ k))[0]
    x_model = R.T @ np.array([0.0, 1.0, 0.0])  # true north in the model frame
    xl = L @ x_model
    az_l = np.degrees(np.arctan2(xl[0], xl[1]))
    return zen, float(az_l % 360.0)


def fit_lobe_coeff(s_meas, vbar, s_ref) -> float:
    """Least-squares coefficient (deg) of the lobe-offset model: the in-plane-of-incidence
    error of the measured directions against reference directions, proportional to tan(theta_i)."""
    from ..vision.mirror import incidence_frame

    num = den = 0.0
    for s, vb, r in zip(np.asarray(s_meas, float), np.asarray(vbar, float), np.asarray(s_ref, float)):
        t, inc = incidence_frame(s, vb)
        e = float(np.degrees((s - r) @ inc))
        num += t * e
        den += t * t
    return num / den if den > 0 else 0.0


def fit_rotation_and_lobe(s_meas, vbar, s_enu, iters: int = 4):
    """Alternate the full ephemeris rotation fit and the lobe coefficient fit.
    Returns (zenith_model, offset_deg, coeff_deg)."""
    from ..vision.mirror import level_rotation, lobe_correct

    s_meas = np.asarray(s_meas, float)
    s_enu = np.asarray(s_enu, float)
    k = 0.0
    for _ in range(iters):
        sc = np.array([lobe_correct(s, vb, k) for s, vb in zip(s_meas, vbar)]) if k else s_meas
        zen, off = ephemeris_rotation(sc, s_enu)
        # model-frame reference directions from the fitted rotation
        L = level_rotation(zen)
        a = np.radians(off)
        Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])
        R = Rz @ L  # v_enu = R v_model  (az_enu = az_lev - off)
        s_ref = s_enu @ R  # R^T v
        k = fit_lobe_coeff(s_meas, vbar, s_ref)
    return zen, off, k
