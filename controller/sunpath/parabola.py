"""The seed paper's sun-path model: a daily least-squares parabola of elevation over time.

``Elv(T) = c0 + c1 T + c2 T^2`` with ``T`` in hours of the local clock (since the local
midnight of the day).  Yesterday's coefficients enter today's adjustment as weighted
pseudo-observations (weight = inverse of their covariance), and today's elevations are
weighted by the inverse of yesterday's a-posteriori variance factor, so that even one
morning observation gives today's parabola.  Solar noon is the parabola's extremum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .days import DayResult, split_days
from .ephemeris import geocentric_sun, wrap180
from .localisation import culmination_side, declination_from_noon, latitude_from_noon, longitude_from_noon

#: Variance (deg^2) of one elevation observation assumed when no fit can tell it.
DEFAULT_VARIANCE = 0.3 ** 2


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


def fit_parabola(T_h, el_deg, prior: ParabolaFit | None = None,
                 default_variance: float = DEFAULT_VARIANCE, midnight: float = 0.0
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


def run_seed(times, az_deg, el_deg, utc_offset_h: float | None = None,
             lat_deg: float | None = None, use_prior: bool = True,
             window_h: float | None = None, noon_elevation: str = "measured",
             transit_tolerance_s: float | None = None
             ) -> tuple[list[DayResult], list[ParabolaFit]]:
    """The paper's method over a series of observations, one result per local day.

    Each day is fitted with yesterday's fit as prior when yesterday (the previous local
    date) was fitted too; after a longer break the day is fitted alone, because the prior
    assumes the noon elevation changed little.  Latitude comes from the noon elevation and
    the SPA declination; longitude from the noon time and SPA's equation of time; the
    declination ``el_noon + lat - 90`` needs ``lat_deg`` (nan without it).  The culmination
    side is read from the observed azimuth at the elevation maximum (ENU azimuths).

    ``window_h`` (not in the paper) keeps only observations within that many hours of
    noon (located by a first fit of the whole day): elevation is a parabola of time only
    near noon, and a whole-day fit biases the extremum (see docs/sunpath.md).

    ``noon_elevation`` is the ``Elv_n`` of the declination and latitude formulas:

    * ``"measured"`` (default, the paper's section 3-2: "the sun's elevation measured at
      the moment it crosses the meridian"): the observation nearest the fitted noon, if it
      is within ``transit_tolerance_s`` of it (default: half the day's median sampling
      interval, i.e. the frame at the transit).  Without one (clouds at noon) the day has
      no measured ``Elv_n``, and its declination and latitude are nan.
    * ``"vertex"`` (a labelled variant): the parabola's extremum value.  Over a whole day
      the elevation is not a parabola of time and this value lies 1-6 deg below the true
      noon elevation (docs/sunpath.md).

    Returns
    -------
    results : list of DayResult
    fits : list of ParabolaFit (same order)
    """
    if noon_elevation not in ("measured", "vertex"):
        raise ValueError(f"noon_elevation must be 'measured' or 'vertex', got "
                         f"{noon_elevation!r}")
    t = np.asarray(times, dtype=float)
    az = np.asarray(az_deg, dtype=float)
    el = np.asarray(el_deg, dtype=float)
    results, fits = [], []
    prev_fit, prev_num = None, None
    for day in split_days(t, utc_offset_h):
        idx = day.index
        prior = prev_fit if (use_prior and prev_num == day.day_number - 1) else None
        if idx.size < 3 and prior is None:
            continue
        T = (t[idx] - day.midnight) / 3600.0
        fit = fit_parabola(T, el[idx], prior=prior, midnight=day.midnight)
        if window_h is not None:
            for _ in range(2):  # re-centre the window on the refined noon
                keep = np.abs(T - fit.noon_hours) <= window_h
                if keep.sum() < 3 and prior is None:
                    break
                fit = fit_parabola(T[keep], el[idx][keep], prior=prior, midnight=day.midnight)
        if not (fit.coef[2] < 0 and 0 <= fit.noon_hours <= 24):
            continue  # no maximum inside the day: nothing to learn
        noon = fit.noon_utc
        side = culmination_side(_az_near(t[idx], az[idx], noon))
        dec_eph = float(geocentric_sun(noon).dec_deg[0])
        if noon_elevation == "vertex":
            el_n = fit.noon_el_deg
        else:
            el_n = _measured_at_transit(t[idx], el[idx], noon, transit_tolerance_s)
        lat = float(latitude_from_noon(el_n, dec_eph, side))
        dec = (float(declination_from_noon(el_n, lat_deg, side))
               if lat_deg is not None else float("nan"))
        try:
            off = azimuth_offset_at_culmination(az[idx], el[idx], side) if idx.size >= 3 \
                else float("nan")
        except np.linalg.LinAlgError:
            off = float("nan")
        results.append(DayResult(
            date=day.date, noon_utc=noon, noon_el_deg=el_n, declination_deg=dec,
            lat_deg=lat, lon_deg=float(longitude_from_noon(noon)[0]), n_obs=int(idx.size),
            method="seed", az_offset_deg=off, noon_sigma_s=fit.noon_sigma_s))
        fits.append(fit)
        prev_fit, prev_num = fit, day.day_number
    return results, fits


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
