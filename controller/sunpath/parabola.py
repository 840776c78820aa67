"""The seed paper's sun-path model: a daily least-squares parabola of elevation over time.

``Elv(T) = c0 + c1 T + c2 T^2`` with ``T`` in hours of the local clock (since the local
midnight of the day).  Solar noon is the parabola's extremum.  Each day's noon (the
paper's Table 3) comes from that day's own observations, fitted on samples balanced about
noon (:func:`fit_mirrored`; the paper fits "over the interval before to after solar
noon").  For prediction (the paper's Table 4) yesterday's coefficients enter today's
adjustment as weighted pseudo-observations (weight = inverse of their covariance), and
today's elevations are weighted by the inverse of yesterday's a-posteriori variance
factor, so that even one morning observation gives today's parabola.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .days import Day, DayResult, split_days
from .ephemeris import geocentric_sun, wrap180
from .localisation import culmination_side, declination_from_noon, latitude_from_noon, longitude_from_noon
from .mirror import default_tolerance, mirrored_mask, nearest_centre

#: Variance (deg^2) of one elevation observation assumed when no fit can tell it.
DEFAULT_VARIANCE = 0.3**2
#: Fit windows of the daily parabola: balanced about noon (default) or every sample.
FITS = ("mirrored", "whole-day")
#: What ``Elv_n`` (the noon elevation of the declination and latitude formulas) is.
NOON_ELEVATIONS = ("measured", "vertex")


@dataclass(frozen=True)
class ParabolaFit:
    """Result of one day's adjustment.

    Attributes
    ----------
    coef : ndarray, shape (3,)
        ``(c0, c1, c2)`` in deg, deg/h, deg/h^2.
    cov : ndarray, shape (3, 3)
        Covariance of ``coef`` (a-posteriori variance factor times inverse normal matrix).
    variance : float
        A-posteriori variance of one elevation observation, deg^2 (the weight unit for
        tomorrow's observations).
    n_obs : int
        Elevation observations used (pseudo-observations not counted).
    midnight : float
        POSIX seconds of ``T = 0``.
    used_prior : bool
        Whether yesterday's coefficients entered the adjustment.
    """

    coef: np.ndarray
    cov: np.ndarray
    variance: float
    n_obs: int
    midnight: float
    used_prior: bool = False

    @property
    def noon_hours(self) -> float:
        """Extremum ``T = -c1 / (2 c2)`` (local hours)."""
        _, c1, c2 = self.coef
        return float(-c1 / (2.0 * c2))

    @property
    def noon_utc(self) -> float:
        """Extremum as POSIX seconds."""
        return self.midnight + 3600.0 * self.noon_hours

    @property
    def noon_el_deg(self) -> float:
        """Elevation at the extremum, deg."""
        c0, c1, c2 = self.coef
        return float(c0 - c1 * c1 / (4.0 * c2))

    @property
    def noon_sigma_s(self) -> float:
        """One-sigma of the noon time (s), first-order propagation of ``cov``."""
        _, c1, c2 = self.coef
        g = np.array([0.0, -1.0 / (2 * c2), c1 / (2 * c2 * c2)])
        return float(3600.0 * np.sqrt(max(g @ self.cov @ g, 0.0)))

    def elevation(self, t) -> np.ndarray:
        """Parabola elevation (deg) at POSIX times ``t``."""
        T = (np.asarray(t, dtype=float) - self.midnight) / 3600.0
        return self.coef[0] + self.coef[1] * T + self.coef[2] * T * T


def fit_parabola(
    T_h,
    el_deg,
    prior: ParabolaFit | None = None,
    default_variance: float = DEFAULT_VARIANCE,
    midnight: float = 0.0,
) -> ParabolaFit:
    """Weighted least-squares parabola of elevation over local hours, with optional prior.

    Parameters
    ----------
    T_h : array_like
        Local hours since ``midnight``.
    el_deg : array_like
        Observed elevations, deg.
    prior : ParabolaFit, optional
        Yesterday's fit: its coefficients are pseudo-observations with weight
        ``inv(prior.cov)`` and today's observations get weight ``1 / prior.variance``.
    default_variance : float
        Observation variance (deg^2) when there is no prior and no redundancy.
    midnight : float
        POSIX seconds of ``T = 0`` (stored in the result).

    Returns
    -------
    ParabolaFit

    Raises
    ------
    ValueError
        Fewer than 3 observations without a prior.
    """
    T = np.asarray(T_h, dtype=float)
    y = np.asarray(el_deg, dtype=float)
    n = T.size
    A = np.column_stack([np.ones(n), T, T * T])
    if prior is None:
        if n < 3:
            raise ValueError("a parabola needs at least 3 observations without a prior")
        N = A.T @ A
        c = np.linalg.solve(N, A.T @ y)
        v = y - A @ c
        red = n - 3
        var = float(v @ v / red) if red > 0 else default_variance
        return ParabolaFit(c, var * np.linalg.inv(N), var, n, midnight, False)
    w = 1.0 / prior.variance
    Wp = np.linalg.inv(prior.cov)
    N = w * (A.T @ A) + Wp
    c = np.linalg.solve(N, w * (A.T @ y) + Wp @ prior.coef)
    v = y - A @ c
    dc = c - prior.coef
    red = max(n, 1)  # n observations + 3 pseudo-observations - 3 unknowns
    s0 = float((w * (v @ v) + dc @ Wp @ dc) / red)  # variance factor of unit weight
    return ParabolaFit(c, s0 * np.linalg.inv(N), s0 * prior.variance, n, midnight, True)


def azimuth_offset_at_culmination(az_deg, el_deg, culmination: str = "south") -> float:
    """Sensor azimuth offset (deg) from one day: parabola of elevation over azimuth.

    At the extremum of ``el(az)`` the true azimuth is 180 (``"south"``) or 0 (``"north"``);
    the returned offset is sensor azimuth minus true azimuth, to be subtracted from later
    sensor azimuths (the paper's section 2-6-2).
    """
    az = np.unwrap(np.radians(np.asarray(az_deg, dtype=float)))
    az = np.degrees(az)
    ref = float(np.median(az))
    fit = fit_parabola(az - ref, el_deg)
    az_top = ref + fit.noon_hours  # "hours" here are degrees of azimuth
    true = 180.0 if culmination == "south" else 0.0
    return float(wrap180(az_top - true) % 360.0)


@dataclass(frozen=True)
class MirroredFit:
    """A day's parabola fitted on samples mirrored about noon (:func:`fit_mirrored`).

    Attributes
    ----------
    fit : ParabolaFit
        The parabola of the balanced set.
    keep : ndarray of bool
        Which of the input samples form the balanced set.
    centre_h : float
        Centre of symmetry, hours (a grid point or half-step of the sampling).
    iterations : int
        Fits on balanced sets until the centre stopped moving.
    converged : bool
        False when the centre cycled between neighbours; then the fit whose vertex lies
        nearest its own centre is kept.
    """

    fit: ParabolaFit
    keep: np.ndarray
    centre_h: float
    iterations: int
    converged: bool


def fit_mirrored(
    T_h,
    el_deg,
    prior: ParabolaFit | None = None,
    midnight: float = 0.0,
    tolerance_h: float | None = None,
    half_width_h: float | None = None,
    max_iter: int = 10,
) -> MirroredFit | None:
    """Parabola fitted on the samples mirrored about the fitted noon, iterated.

    Starts from the fit of every sample, then repeats: centre = the grid point or
    half-step nearest the fitted noon (:func:`~controller.sunpath.mirror.nearest_centre`),
    keep the samples paired symmetrically about it
    (:func:`~controller.sunpath.mirror.mirrored_mask`), refit.  It stops when the centre
    no longer moves.  No truth is used.

    Parameters
    ----------
    T_h : array_like
        Local hours since ``midnight``.
    el_deg : array_like
        Observed elevations, deg.
    prior : ParabolaFit, optional
        Yesterday's fit as pseudo-observations (see :func:`fit_parabola`); not used for the
        paper's Table 3, where each day stands alone.
    midnight : float
        POSIX seconds of ``T = 0``.
    tolerance_h : float, optional
        Pairing tolerance, hours (default a tenth of the median sampling interval).
    half_width_h : float, optional
        Keep only pairs within this many hours of the centre (a balanced window).
    max_iter : int
        Most refits.

    Returns
    -------
    MirroredFit or None
        None when no balanced set of at least 3 samples exists (e.g. clouds all
        afternoon) or a fit has no maximum.
    """
    T = np.asarray(T_h, dtype=float)
    y = np.asarray(el_deg, dtype=float)
    if T.size == 0 or (T.size < 3 and prior is None):
        return None
    tol = default_tolerance(T) if tolerance_h is None else float(tolerance_h)
    fit = fit_parabola(T, y, prior=prior, midnight=midnight)
    tried: dict[float, MirroredFit] = {}
    for it in range(1, max_iter + 1):
        if not fit.coef[2] < 0:
            return None  # no maximum: no noon to centre on
        centre = nearest_centre(T, fit.noon_hours)
        if centre in tried:  # cycling between neighbouring centres
            best = min(tried.values(), key=lambda m: abs(m.fit.noon_hours - m.centre_h))
            return MirroredFit(best.fit, best.keep, best.centre_h, it - 1, False)
        keep = mirrored_mask(T, centre, tol, half_width_h)
        if keep.sum() < 3 and prior is None:
            return None
        fit = fit_parabola(T[keep], y[keep], prior=prior, midnight=midnight)
        tried[centre] = MirroredFit(fit, keep, centre, it, True)
        if fit.coef[2] < 0 and nearest_centre(T, fit.noon_hours) == centre:
            return tried[centre]
    return None if not fit.coef[2] < 0 else MirroredFit(fit, keep, centre, max_iter, False)


def run_seed(
    times,
    az_deg,
    el_deg,
    utc_offset_h: float | None = None,
    lat_deg: float | None = None,
    use_prior: bool = False,
    window_h: float | None = None,
    noon_elevation: str = "measured",
    transit_tolerance_s: float | None = None,
    fit: str = "mirrored",
) -> tuple[list[DayResult], list[ParabolaFit]]:
    """The paper's method over a series of observations, one result per local day.

    Each day's noon is the extremum of that day's own parabola (the paper's Table 3).
    Latitude comes from the noon elevation and the SPA declination; longitude from the noon
    time and SPA's equation of time; the declination ``el_noon + lat - 90`` needs
    ``lat_deg`` (nan without it).  The culmination side is read from the observed azimuth
    nearest the noon (ENU azimuths).

    Parameters
    ----------
    times : array_like
        POSIX seconds (UTC).
    az_deg, el_deg : array_like
        Observed azimuth (clockwise from north) and elevation, deg.
    utc_offset_h : float, optional
        Civil offset that cuts the days (default: a pseudo-solar clock, see
        :func:`~controller.sunpath.days.local_offset_s`).
    lat_deg : float, optional
        Known latitude, deg north, for the declination formula.
    use_prior : bool
        A labelled variant, not the paper's Table 3: fit each day with yesterday's fit as
        prior when yesterday (the previous local date) was fitted too.  Chained over a run
        of consecutive days without any widening, this averages the days.
    window_h : float, optional
        Keep only observations within this many hours of noon (not in the paper).  With
        ``fit="whole-day"`` the window ``|T - noon| <= window_h`` is re-centred twice on the
        refined noon; with ``"mirrored"`` only the mirrored pairs within it are kept.
    noon_elevation : {"measured", "vertex"}
        The ``Elv_n`` of the declination and latitude formulas.  ``"measured"`` (default,
        the paper's section 3-2: "the sun's elevation measured at the moment it crosses
        the meridian"): the observation nearest the fitted noon, if it is within
        ``transit_tolerance_s`` of it (default: half the day's median sampling interval,
        i.e. the frame at the transit); without one (clouds at noon) the day's
        declination and latitude are nan.  ``"vertex"`` (a labelled variant): the
        parabola's extremum value, 1-6 deg below the true noon elevation over a whole day.
    transit_tolerance_s : float, optional
        See ``noon_elevation``.
    fit : {"mirrored", "whole-day"}
        ``"mirrored"`` (default): the parabola of the samples mirrored about the fitted
        noon, iterated (:func:`fit_mirrored`); a day without a balanced set of 3 samples
        gives no row.  ``"whole-day"`` (a labelled variant): every sample of the day; its
        vertex is pulled towards the centre of the sampling window (docs/sunpath.md).

    Returns
    -------
    results : list of DayResult
    fits : list of ParabolaFit (same order)
    """
    if noon_elevation not in NOON_ELEVATIONS:
        raise ValueError(f"noon_elevation must be 'measured' or 'vertex', got {noon_elevation!r}")
    if fit not in FITS:
        raise ValueError(f"fit must be 'mirrored' or 'whole-day', got {fit!r}")
    t = np.asarray(times, dtype=float)
    az = np.asarray(az_deg, dtype=float)
    el = np.asarray(el_deg, dtype=float)
    fitted: list[tuple[Day, ParabolaFit]] = []
    prev_fit: ParabolaFit | None = None
    prev_num: int | None = None
    for day in split_days(t, utc_offset_h, el):
        prior = prev_fit if (use_prior and prev_num == day.day_number - 1) else None
        day_fit = _day_fit(
            (t[day.index] - day.midnight) / 3600.0, el[day.index], prior, day.midnight, fit, window_h
        )
        if day_fit is None or not (day_fit.coef[2] < 0 and 0 <= day_fit.noon_hours <= 24):
            continue  # no maximum inside the day: nothing to learn
        fitted.append((day, day_fit))
        prev_fit, prev_num = day_fit, day.day_number
    if not fitted:
        return [], []
    # One vectorised SPA call for all days (the per-day calls were most of the run time).
    noons = np.array([f.noon_utc for _, f in fitted])
    dec_eph = geocentric_sun(noons).dec_deg
    lon = longitude_from_noon(noons)
    results: list[DayResult] = []
    for k, (day, day_fit) in enumerate(fitted):
        idx = day.index
        noon = float(noons[k])
        side = culmination_side(_az_near(t[idx], az[idx], noon))
        if noon_elevation == "vertex":
            el_n = day_fit.noon_el_deg
        else:
            el_n = _measured_at_transit(t[idx], el[idx], noon, transit_tolerance_s)
        lat = float(latitude_from_noon(el_n, float(dec_eph[k]), side))
        dec = float(declination_from_noon(el_n, lat_deg, side)) if lat_deg is not None else float("nan")
        try:
            off = azimuth_offset_at_culmination(az[idx], el[idx], side) if idx.size >= 3 else float("nan")
        except np.linalg.LinAlgError:
            off = float("nan")
        results.append(
            DayResult(
                date=day.date,
                noon_utc=noon,
                noon_el_deg=el_n,
                declination_deg=dec,
                lat_deg=lat,
                lon_deg=float(lon[k]),
                n_obs=int(idx.size),
                method="seed",
                az_offset_deg=off,
                noon_sigma_s=day_fit.noon_sigma_s,
            )
        )
    fits = [f for _, f in fitted]
    return results, fits


def _day_fit(
    T, el, prior: ParabolaFit | None, midnight: float, fit: str, window_h: float | None
) -> ParabolaFit | None:
    """One day's parabola over local hours ``T``; None when the day cannot give one."""
    if T.size < 3 and prior is None:
        return None
    if fit == "mirrored":
        m = fit_mirrored(T, el, prior=prior, midnight=midnight, half_width_h=window_h)
        return None if m is None else m.fit
    out = fit_parabola(T, el, prior=prior, midnight=midnight)
    if window_h is not None:
        for _ in range(2):  # re-centre the window on the refined noon
            keep = np.abs(T - out.noon_hours) <= window_h
            if keep.sum() < 3 and prior is None:
                break
            out = fit_parabola(T[keep], el[keep], prior=prior, midnight=midnight)
    return out


def _measured_at_transit(t, el, noon: float, tolerance_s: float | None) -> float:
    """Observed elevation at the transit ``noon``: the nearest observation, if close enough.

    The default tolerance is half the median interval between the day's observations: the
    frame taken at the transit on a regular schedule.  nan when no observation is that
    close (the sun was hidden around noon).
    """
    if tolerance_s is None:
        dt = np.diff(np.sort(t))
        tolerance_s = 0.5 * float(np.median(dt)) if dt.size else 0.0
    i = int(np.argmin(np.abs(t - noon)))
    return float(el[i]) if abs(t[i] - noon) <= tolerance_s else float("nan")


def _az_near(t, az, t0) -> float:
    """Observed azimuth nearest in time to ``t0``."""
    return float(az[int(np.argmin(np.abs(t - t0)))])
