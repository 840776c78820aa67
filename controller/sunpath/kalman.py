"""A physical sun-path model in an extended Kalman filter (filterpy).

State vector (degrees unless stated)::

    0 lat      site latitude, north-positive
    1 lon      site longitude, east-positive (equivalently the noon offset: 1 deg = 240 s)
    2 dec      ``declination="free"``: u = sin(eps) sin(lambda) = sin(declination)
               (dimensionless); ``declination="ephemeris"``: a correction (deg) added to
               SPA's geocentric declination
    3 dec_rate ``free``: v = sin(eps) cos(lambda) (dimensionless); ``ephemeris``: the
               correction's daily drift, deg/day
    4 az_off   sensor azimuth minus true azimuth
    5 refr     refraction scale (1 = SPA's standard atmosphere)

The measurement model ``h(x, t)`` is spherical astronomy: the hour angle is SPA's apparent
sidereal time plus ``lon`` minus the sun's right ascension (i.e. UTC, longitude and the
equation of time), and azimuth and elevation follow from hour angle, declination and
latitude (:func:`~controller.sunpath.ephemeris.azel_from_hour_angle`).  The innovation is
expressed in the sky's tangent plane, ``(d_az cos(el), d_el)``, so it stays well defined
near the zenith and one isotropic sigma describes the sensor.  The Jacobian is numeric.

In ``free`` mode (sky only: declination from the observations alone) the declination
follows the law of the sun's orbit, ``sin(dec) = sin(eps) sin(lambda)``: the state holds the vector
``(u, v) = sin(eps) (sin lambda, cos lambda)``, whose length is ``sin(eps)`` (obliquity)
and whose angle is the sun's ecliptic longitude ``lambda``.  Between two times the vector
is rotated by the advance of ``lambda``: the orbital rate, i.e. the mean motion
0.98564736 deg/day plus Kepler's equation of centre (eccentricity 0.0167, perihelion in
early January), or the mean motion alone (``orbit_rate="mean"``).  The rotation is linear,
so the covariance propagates exactly.  The obliquity (23.4393 deg) enters once, as a
pseudo-observation of the vector's length, once the data have told the sign of ``v``
(whether the sun is moving north or south).  ``lambda`` itself, i.e. the declination, is
never taken from an ephemeris: it is learnt from the observed elevations.  A multi-week
break is bridged by the orbit, not by a constant rate.  In ``ephemeris`` mode ``dec`` is a
small correction to SPA's declination with a linear drift.  Both modes use SPA's right
ascension (the equation of time) in the hour angle, as the paper's longitude formula does.

Without a site the filter starts from a batch fit (scipy least squares from a coarse grid)
of the first few hours of observations; with a site it starts from the site after the
first observation (``ephemeris`` mode) or after three observations half an hour apart
(``free`` mode, whose declination comes from a grid and a fit, not from the ephemeris).  Process noise is continuous in time, so a night
or a cloudy week widens the covariance by the right amount and the state carries over.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy import optimize

from ..sun.source import Site
from ..sun.types import SunObservation
from .days import DayResult, split_days
from .ephemeris import (GeocentricSun, azel_from_hour_angle, geocentric_sun, transit_time,
                        wrap180)

LAT, LON, DEC, RATE, AZOFF, REFR = range(6)
STATE_NAMES = ("lat_deg", "lon_deg", "dec_deg", "dec_rate_deg_per_day", "az_offset_deg",
               "refraction_scale")
STATE_NAMES_FREE = ("lat_deg", "lon_deg", "orbit_u_sin_dec", "orbit_v", "az_offset_deg",
                    "refraction_scale")
#: Version tag of the ``free`` mode's declination states (u, v); older state files held
#: (declination deg, rate deg/day) and are converted on load.
FREE_MODEL = "orbit-uv-1"
#: Mean obliquity of the ecliptic (deg), IAU, J2000 (drifts 0.013 deg per century).
OBLIQUITY_DEG = 23.4393
#: Mean motion of the sun in ecliptic longitude, deg/day (tropical year).
MEAN_MOTION_DEG_PER_DAY = 0.98564736
_DAY = 86400.0
#: Angular frequency of the seasons, rad/day (tropical year 365.2422 days).
OMEGA_YEAR = 2.0 * np.pi / 365.2422


def orbit_advance_deg(t0, t1, rate: str = "kepler"):
    """Advance of the sun's ecliptic longitude (deg) from POSIX ``t0`` to ``t1``.

    ``"mean"``: the mean motion only.  ``"kepler"``: plus the change of Kepler's equation of
    centre, ``C(M) = 1.914602 sin M + 0.019993 sin 2M + 0.000289 sin 3M`` with the mean
    anomaly ``M = 357.52911 + 0.98560028 d`` (d = days from J2000), i.e. the orbital rate
    of a Keplerian orbit with eccentricity 0.0167.  Only differences of longitude are
    returned; the longitude itself (the date in the tropical year, hence the declination)
    is the filter's state, learnt from the sky.
    """
    d0 = (np.asarray(t0, dtype=float) / _DAY) - 10957.5
    d1 = (np.asarray(t1, dtype=float) / _DAY) - 10957.5
    adv = MEAN_MOTION_DEG_PER_DAY * (d1 - d0)
    if rate == "mean":
        return adv
    if rate != "kepler":
        raise ValueError(f"orbit_rate must be 'kepler' or 'mean', got {rate!r}")

    def centre(d):
        m = np.radians(357.52911 + 0.98560028 * d)
        return 1.914602 * np.sin(m) + 0.019993 * np.sin(2 * m) + 0.000289 * np.sin(3 * m)

    return adv + centre(d1) - centre(d0)


@dataclass
class KalmanConfig:
    """Tuning of :class:`SunPathKalman` (variances in deg^2, rates per day).

    Attributes
    ----------
    declination : str
        ``"ephemeris"`` (default: SPA's geocentric declination, which needs only UTC, plus
        a learnt correction) or ``"free"`` (sky only: declination learnt from the
        observations through the orbit law; the mode in which declination is measured, as
        the paper measures it).
    orbit_rate : str
        ``free`` mode: advance of the ecliptic longitude between two times, ``"kepler"``
        (mean motion plus equation of centre) or ``"mean"`` (mean motion only).
    obliquity_deg, obliquity_sigma_deg : float
        ``free`` mode: the obliquity pseudo-observation (``sigma <= 0`` disables it).
    q_orbit : float
        ``free`` mode: random walk on (u, v), 1/day (covers nutation, aberration and the
        lunar and planetary terms the orbit law leaves out).
    iterations : int
        Measurement-update iterations (1 = filterpy's EKF update; more = iterated EKF).
    gate_chi2 : float
        Innovation gate on the squared Mahalanobis distance (2 dof; 13.8 = 99.9 %).
    max_consecutive_rejects : int
        After this many gated observations in a row the covariance is inflated, so a
        filter that has drifted cannot lock itself out.
    q_site, q_dec, q_rate, q_az_off, q_refr : float
        Process noise densities: random walks on site (deg^2/day), declination
        (deg^2/day), declination rate (deg^2/day^3, integrated random walk), azimuth
        offset (deg^2/day) and refraction scale (1/day).
    sigma_lat, sigma_lon, sigma_dec, sigma_rate, sigma_az_off, sigma_refr : float
        Prior one-sigma values when that quantity is not given.
    site_sigma_deg : float
        One-sigma of a given site's latitude and longitude.
    init_min_obs, init_min_span_h, init_max_sigma_deg : float
        Without a site, start the filter once this many observations span this many hours
        and the batch fit gives latitude and longitude to within this one-sigma.
    pressure_hpa, temp_c : float
        Atmosphere for the refraction model (scaled by the ``refr`` state).
    """

    declination: str = "ephemeris"
    orbit_rate: str = "kepler"
    obliquity_deg: float = OBLIQUITY_DEG
    obliquity_sigma_deg: float = 0.01
    q_orbit: float = 1e-9
    iterations: int = 1
    gate_chi2: float = 13.8
    max_consecutive_rejects: int = 6
    q_site: float = 1e-8
    q_dec: float = 1e-6
    q_rate: float = 2e-5  # unused since the orbit model; kept so old state files load
    q_rate_ephemeris: float = 3e-8
    q_az_off: float = 1e-4
    q_refr: float = 1e-4
    sigma_lat: float = 30.0
    sigma_lon: float = 30.0
    sigma_dec: float = 15.0
    sigma_rate: float = 0.3
    sigma_az_off: float = 30.0
    sigma_refr: float = 0.1
    site_sigma_deg: float = 0.01
    init_min_obs: int = 12
    init_min_span_h: float = 3.0
    init_max_sigma_deg: float = 2.0
    pressure_hpa: float = 1013.25
    temp_c: float = 12.0


@dataclass(frozen=True)
class UpdateResult:
    """What the filter did with one observation."""

    accepted: bool
    mahalanobis2: float
    initialised: bool
    reason: str = ""


@dataclass(frozen=True)
class Prediction:
    """Predicted sun direction (ENU) with covariance of (azimuth, elevation), deg^2."""

    time: float
    az_deg: float
    el_deg: float
    covariance: np.ndarray = field(repr=False)

    @property
    def sigma_deg(self) -> float:
        c = np.cos(np.radians(self.el_deg))
        return float(np.sqrt(max(self.covariance[0, 0] * c * c + self.covariance[1, 1], 0.0)))


class SunPathKalman:
    """Extended Kalman filter over the sun's apparent path; see the module docstring.

    Parameters
    ----------
    config : KalmanConfig, optional
    site : Site, optional
        Known site: latitude and longitude start at it with ``config.site_sigma_deg``.
    """

    def __init__(self, config: KalmanConfig | None = None, site: Site | None = None):
        self.config = config or KalmanConfig()
        self.site = site
        mode = self.config.declination
        if mode not in ("free", "ephemeris"):
            raise ValueError(f"declination mode must be 'free' or 'ephemeris', got {mode!r}")
        self.mode = mode
        self.ekf = ExtendedKalmanFilter(dim_x=6, dim_z=2)
        self.t: float | None = None  # time the state refers to
        self.initialised = False
        self.buffer: list[SunObservation] = []
        self.consecutive_rejects = 0
        self.n_accepted = 0
        self.n_rejected = 0
        self.obliquity_applied = False

    # ------------------------------------------------------------------ state access
    @property
    def x(self) -> np.ndarray:
        return self.ekf.x

    @property
    def P(self) -> np.ndarray:
        return self.ekf.P

    def sigma(self, i: int) -> float:
        return float(np.sqrt(max(self.ekf.P[i, i], 0.0)))

    # ------------------------------------------------------------------ model
    def _dec(self, x, geo: GeocentricSun, i=0):
        if self.mode == "free":
            return float(np.degrees(np.arcsin(np.clip(x[DEC], -1.0, 1.0))))
        return x[DEC] + geo.dec_deg[i]

    def _azel(self, x, geo: GeocentricSun, i=0):
        """Model (sensor azimuth, elevation) for state ``x`` at the time of ``geo[i]``."""
        h = wrap180(geo.sidereal_deg[i] + x[LON] - geo.ra_deg[i])
        az, el = azel_from_hour_angle(h, self._dec(x, geo, i), x[LAT], x[REFR],
                                      self.config.pressure_hpa, self.config.temp_c)
        return float(az) + x[AZOFF], float(el)

    def _jacobian(self, x, geo, i=0, scaled=True):
        """Numeric Jacobian of ``(az cos(el), el)`` (``scaled``) or ``(az, el)`` w.r.t. x."""
        az0, el0 = self._azel(x, geo, i)
        c = np.cos(np.radians(el0)) if scaled else 1.0
        J = np.zeros((2, 6))
        for k, step in enumerate((1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4)):
            xp, xm = x.copy(), x.copy()
            xp[k] += step
            xm[k] -= step
            azp, elp = self._azel(xp, geo, i)
            azm, elm = self._azel(xm, geo, i)
            J[0, k] = float(wrap180(azp - azm)) / (2 * step) * c
            J[1, k] = (elp - elm) / (2 * step)
        return J

    @staticmethod
    def _residual(z, hx):
        """Tangent-plane residual ``(d_az cos(el), d_el)`` in deg."""
        return np.array([float(wrap180(z[0] - hx[0])) * np.cos(np.radians(hx[1])),
                         z[1] - hx[1]])

    # ------------------------------------------------------------------ time update
    def _transition(self, t0: float, t1: float):
        """Transition matrix and process noise from POSIX ``t0`` to ``t1``."""
        d = (t1 - t0) / _DAY
        ad = abs(d)
        F = np.eye(6)
        c = self.config
        Q = np.zeros((6, 6))
        if self.mode == "free":  # rotate (u, v) by the advance of the ecliptic longitude
            th = np.radians(orbit_advance_deg(t0, t1, c.orbit_rate))
            F[DEC, DEC] = F[RATE, RATE] = np.cos(th)
            F[DEC, RATE] = np.sin(th)
            F[RATE, DEC] = -np.sin(th)
            Q[DEC, DEC] = Q[RATE, RATE] = c.q_orbit * ad
        else:  # correction to SPA: constant plus slow drift
            F[DEC, RATE] = d
            qr = c.q_rate_ephemeris
            Q[DEC, DEC] = c.q_dec * ad + qr * ad ** 3 / 3
            Q[DEC, RATE] = Q[RATE, DEC] = qr * d * d / 2
            Q[RATE, RATE] = qr * ad
        Q[LAT, LAT] = Q[LON, LON] = c.q_site * ad
        Q[AZOFF, AZOFF] = c.q_az_off * ad
        Q[REFR, REFR] = c.q_refr * ad
        return F, Q

    def _propagate(self, t: float) -> None:
        F, Q = self._transition(self.t, float(t))
        self.ekf.F, self.ekf.Q = F, Q
        self.ekf.predict()
        self.t = float(t)

    def _propagated(self, t: float):
        F, Q = self._transition(self.t, float(t))
        return F @ self.ekf.x, F @ self.ekf.P @ F.T + Q

    def _apply_obliquity(self) -> None:
        """``free`` mode: the obliquity as one pseudo-observation of ``|(u, v)|``.

        Applied once, when the data have told the sign of ``v`` (sun moving north or
        south) at three sigma; the rotation keeps the vector's length, so the information
        is kept afterwards (apart from the small process noise).
        """
        c = self.config
        if (self.mode != "free" or self.obliquity_applied or c.obliquity_sigma_deg <= 0):
            return
        x, P = self.ekf.x, self.ekf.P
        if abs(x[RATE]) < 3.0 * np.sqrt(max(P[RATE, RATE], 0.0)):
            return
        target = np.sin(np.radians(c.obliquity_deg))
        r_var = (np.cos(np.radians(c.obliquity_deg)) * np.radians(c.obliquity_sigma_deg)) ** 2
        x_i = x.copy()
        for _ in range(3):  # iterated EKF: the norm is nonlinear in (u, v)
            n = float(np.hypot(x_i[DEC], x_i[RATE]))
            Hc = np.zeros(6)
            Hc[DEC], Hc[RATE] = x_i[DEC] / n, x_i[RATE] / n
            S = float(Hc @ P @ Hc) + r_var
            K = P @ Hc / S
            x_i = x + K * (target - n - Hc @ (x - x_i))
        I_KH = np.eye(6) - np.outer(K, Hc)
        self.ekf.x = x_i
        self.ekf.P = I_KH @ P @ I_KH.T + np.outer(K, K) * r_var
        self._normalise()
        self.obliquity_applied = True

    # ------------------------------------------------------------------ updates
    def update(self, obs: SunObservation) -> UpdateResult:
        """Assimilate one observation (sensor-frame azimuth, elevation, sigma)."""
        if not self.initialised:
            self.buffer.append(obs)
            if self._try_initialise():
                return UpdateResult(True, 0.0, True, "initialised")
            return UpdateResult(False, float("nan"), False, "waiting to initialise")
        if obs.time < self.t - 1e-6:
            return UpdateResult(False, float("nan"), True, "older than the state")
        self._propagate(obs.time)
        geo = geocentric_sun(obs.time)
        z = np.array([obs.az_deg, obs.el_deg])
        R = np.eye(2) * obs.sigma_deg ** 2
        H = self._jacobian(self.ekf.x, geo)
        y = self._residual(z, self._azel(self.ekf.x, geo))
        S = H @ self.ekf.P @ H.T + R
        d2 = float(y @ np.linalg.solve(S, y))
        if d2 > self.config.gate_chi2:
            self.consecutive_rejects += 1
            self.n_rejected += 1
            if self.consecutive_rejects >= self.config.max_consecutive_rejects:
                # A run of rejections means the filter, not the sky, is wrong.
                self.ekf.P = self.ekf.P * 25.0
                self.consecutive_rejects = 0
            return UpdateResult(False, d2, True, "gated")
        self.consecutive_rejects = 0
        if self.config.iterations <= 1:
            self.ekf.update(z, lambda x: self._jacobian(x, geo),
                            lambda x: np.array(self._azel(x, geo)), R=R,
                            residual=self._residual)
        else:
            self._iterated_update(z, R, geo, H, y)
        self._normalise()
        self._apply_obliquity()
        self.n_accepted += 1
        return UpdateResult(True, d2, True)

    def _iterated_update(self, z, R, geo, H, y):
        """Iterated EKF measurement update (Gauss-Newton on the MAP cost).

        Relinearises ``h`` at the updated state; with a wide covariance (the first days
        without a site) this removes most of the single-step EKF's linearisation error.
        """
        x0, P = self.ekf.x.copy(), self.ekf.P
        xi = x0.copy()
        for it in range(self.config.iterations):
            if it:
                H = self._jacobian(xi, geo)
                y = self._residual(z, self._azel(xi, geo))
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            dx = K @ (y - H @ (x0 - xi))
            xn = x0 + dx
            done = np.max(np.abs(xn - xi)) < 1e-7
            xi = xn
            if done:
                break
        I_KH = np.eye(6) - K @ H
        self.ekf.x = xi
        self.ekf.P = I_KH @ P @ I_KH.T + K @ R @ K.T

    def _normalise(self):
        x = self.ekf.x
        x[LON] = float(wrap180(x[LON]))
        x[AZOFF] = float(x[AZOFF] % 360.0)
        self.ekf.P = 0.5 * (self.ekf.P + self.ekf.P.T)

    # ------------------------------------------------------------------ initialisation
    def _prior(self):
        """Prior mean and sigmas (for the batch fit) given what is known."""
        c = self.config
        x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
        s0 = np.array([c.sigma_lat, c.sigma_lon, c.sigma_dec, c.sigma_rate, c.sigma_az_off,
                       c.sigma_refr])
        if self.site is not None:
            x0[LAT], x0[LON] = self.site.latitude, self.site.longitude
            s0[LAT] = s0[LON] = c.site_sigma_deg
        if self.mode == "ephemeris":
            s0[DEC], s0[RATE] = 0.05, 1e-3  # correction to SPA's declination
        return x0, s0

    def _try_initialise(self) -> bool:
        obs = sorted(self.buffer, key=lambda o: o.time)
        t = np.array([o.time for o in obs])
        c = self.config
        known = self.site is not None
        if not known:
            if len(obs) < c.init_min_obs or t[-1] - t[0] < c.init_min_span_h * 3600.0:
                return False
        elif self.mode == "free" and (len(obs) < 3 or t[-1] - t[0] < 1800.0):
            return False  # declination from the sky: a few observations half an hour apart
        t_ref = float(t[-1])
        geo = geocentric_sun(t)
        az = np.array([o.az_deg for o in obs])
        el = np.array([o.el_deg for o in obs])
        sig = np.array([o.sigma_deg for o in obs])
        x0, s0 = self._prior()
        free = [LAT, LON, AZOFF] + ([DEC] if self.mode == "free" else [])
        if known:
            free = [AZOFF] + ([DEC] if self.mode == "free" else [])

        def model(p, fixed):
            x = fixed.copy()
            x[free] = p
            h = wrap180(geo.sidereal_deg + x[LON] - geo.ra_deg)
            d = x[DEC] + (geo.dec_deg if self.mode == "ephemeris" else 0.0)
            m_az, m_el = azel_from_hour_angle(h, d, x[LAT], x[REFR], c.pressure_hpa, c.temp_c)
            return m_az + x[AZOFF], m_el

        def resid(p, fixed):
            m_az, m_el = model(p, fixed)
            r = np.concatenate([wrap180(az - m_az) * np.cos(np.radians(el)) / sig,
                                (el - m_el) / sig])
            x = fixed.copy()
            x[free] = p
            pri = [(x[k] - x0[k]) / s0[k] for k in free if s0[k] < 1.0]
            return np.concatenate([r, pri])

        fixed = x0.copy()
        starts = self._grid_starts(geo, az, el, fixed, free, known)
        best = None
        for p in starts:
            sol = optimize.least_squares(resid, p, args=(fixed,), loss="soft_l1", f_scale=3.0)
            if best is None or sol.cost < best.cost:
                best = sol
        J = best.jac
        n = len(obs)
        # Drop gross outliers before judging the fit.
        r = best.fun[:2 * n].reshape(2, n)
        ok = np.hypot(r[0], r[1]) < 5.0
        try:
            cov = np.linalg.inv(J.T @ J)
        except np.linalg.LinAlgError:
            return False
        x = fixed.copy()
        x[free] = best.x
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        fi = {k: i for i, k in enumerate(free)}
        if not known and (max(sd[fi[LAT]], sd[fi[LON]]) > c.init_max_sigma_deg
                          or ok.mean() < 0.7):
            return False
        P = np.diag(s0 ** 2)
        idx = np.array(free)
        P[np.ix_(idx, idx)] = cov * 4.0  # inflate: the batch fit ignored the rate and refr
        if self.mode == "free":
            # Declination (deg) -> u = sin(dec); v (the direction of motion) still unknown:
            # one sigma sin(eps), i.e. a rate anywhere within the orbit's +-0.4 deg/day.
            dd = float(x[DEC])
            Jc = np.eye(6)
            Jc[DEC, DEC] = np.cos(np.radians(dd)) * np.pi / 180.0
            P = Jc @ P @ Jc.T
            x[DEC] = np.sin(np.radians(dd))
            x[RATE] = 0.0
            P[RATE, :] = P[:, RATE] = 0.0
            P[RATE, RATE] = np.sin(np.radians(c.obliquity_deg)) ** 2
        x[LON] = float(wrap180(x[LON]))
        x[AZOFF] = float(x[AZOFF] % 360.0)
        self.ekf.x = x
        self.ekf.P = 0.5 * (P + P.T)
        self.t = t_ref if not known else float(t[0])
        self.initialised = True
        self.buffer = []
        if known:  # the site gave the geometry: now assimilate every buffered observation
            self.n_accepted += 1  # the first one started the filter
            rest = obs[1:] if len(obs) > 1 else []
            for o in rest:
                self.update(o)
        else:
            self.n_accepted += int(ok.sum())
        return True

    def _grid_starts(self, geo, az, el, fixed, free, known):
        """Starting points: a coarse grid scored with the best constant azimuth offset."""
        c = self.config
        lats = [fixed[LAT]] if known else np.arange(-75.0, 76.0, 7.5)
        lons = [fixed[LON]] if known else np.arange(-180.0, 180.0, 10.0)
        decs = [fixed[DEC]] if self.mode == "ephemeris" else np.arange(-24.0, 24.1, 6.0)
        L, G, D = np.meshgrid(lats, lons, decs, indexing="ij")
        L, G, D = L.ravel()[:, None], G.ravel()[:, None], D.ravel()[:, None]
        h = wrap180(geo.sidereal_deg[None, :] + G - geo.ra_deg[None, :])
        d = D + (geo.dec_deg[None, :] if self.mode == "ephemeris" else 0.0)
        m_az, m_el = azel_from_hour_angle(h, d, L, 1.0, c.pressure_hpa, c.temp_c)
        daz = np.radians(az[None, :] - m_az)
        off = np.degrees(np.arctan2(np.sin(daz).mean(1), np.cos(daz).mean(1)))
        raz = wrap180(az[None, :] - m_az - off[:, None]) * np.cos(np.radians(el))[None, :]
        cost = np.sum(np.minimum(raz ** 2 + (el[None, :] - m_el) ** 2, 25.0), axis=1)
        order = np.argsort(cost)[:4]
        starts = []
        for j in order:
            x = fixed.copy()
            x[LAT], x[LON], x[AZOFF] = L[j, 0], G[j, 0], off[j] % 360.0
            if DEC in free:
                x[DEC] = D[j, 0]
            starts.append(x[free])
        return starts

    # ------------------------------------------------------------------ outputs
    def predict(self, t) -> Prediction:
        """Predicted true (ENU) sun direction at POSIX ``t`` with its covariance.

        The state is not changed.  Raises RuntimeError before initialisation.
        """
        if not self.initialised:
            raise RuntimeError("the sun-path filter has not been initialised yet")
        x, P = self._propagated(float(t))
        geo = geocentric_sun(float(t))
        xe = x.copy()
        xe[AZOFF] = 0.0
        az, el = self._azel(xe, geo)
        J = self._jacobian(xe, geo, scaled=False)
        J[:, AZOFF] = 0.0
        return Prediction(float(t), az % 360.0, el, J @ P @ J.T)

    def noon(self, t_guess: float) -> tuple[float, float]:
        """Solar noon (POSIX s) nearest ``t_guess`` and its one-sigma (s)."""
        x, P = self._propagated(float(t_guess))
        tn = float(transit_time(t_guess, x[LON])[0])
        return tn, float(np.sqrt(P[LON, LON]) * 240.0)

    def declination(self, t: float) -> tuple[float, float]:
        """Declination (deg) at POSIX ``t`` and its one-sigma."""
        x, P = self._propagated(float(t))
        geo = geocentric_sun(float(t))
        dec = float(self._dec(x, geo))
        if self.mode == "free":  # sigma of asin(u)
            return dec, float(np.degrees(np.sqrt(P[DEC, DEC]) / np.cos(np.radians(dec))))
        return dec, float(np.sqrt(P[DEC, DEC]))

    def obliquity_deg(self) -> float:
        """``free`` mode: the obliquity implied by the state, ``asin(|(u, v)|)``, deg."""
        if self.mode != "free":
            return float("nan")
        return float(np.degrees(np.arcsin(min(np.hypot(self.x[DEC], self.x[RATE]), 1.0))))

    def day_result(self, t_guess: float, date: str, n_obs: int, n_rejected: int) -> DayResult:
        """Summarise the current state as the row for the day around ``t_guess``."""
        tn, sn = self.noon(t_guess)
        x, P = self._propagated(tn)
        dec, sdec = self.declination(tn)
        return DayResult(
            date=date, noon_utc=tn, noon_el_deg=self.predict(tn).el_deg, declination_deg=dec,
            lat_deg=float(x[LAT]), lon_deg=float(wrap180(x[LON])), n_obs=n_obs,
            method="kalman", az_offset_deg=float(x[AZOFF] % 360.0), n_rejected=n_rejected,
            noon_sigma_s=sn, lat_sigma_deg=float(np.sqrt(P[LAT, LAT])),
            lon_sigma_deg=float(np.sqrt(P[LON, LON])), dec_sigma_deg=sdec)

    def copy(self) -> "SunPathKalman":
        return copy.deepcopy(self)

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict:
        """JSON-ready snapshot (see :mod:`controller.sunpath.state`)."""
        return {
            "kind": "sunpath-kalman",
            "mode": self.mode,
            "config": asdict(self.config),
            "site": None if self.site is None else asdict(self.site),
            "initialised": self.initialised,
            "t": self.t,
            "state_names": list(STATE_NAMES_FREE if self.mode == "free" else STATE_NAMES),
            "free_model": FREE_MODEL if self.mode == "free" else None,
            "obliquity_applied": self.obliquity_applied,
            # ravel: filterpy starts with a column vector until the filter initialises
            "x": [float(v) for v in np.asarray(self.ekf.x, float).ravel()],
            "P": [[float(v) for v in row] for row in self.ekf.P],
            "buffer": [[o.time, o.az_deg, o.el_deg, o.sigma_deg] for o in self.buffer],
            "n_accepted": self.n_accepted,
            "n_rejected": self.n_rejected,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "SunPathKalman":
        """Inverse of :meth:`to_dict`; raises ValueError/KeyError/TypeError when malformed."""
        if d.get("kind") != "sunpath-kalman":
            raise ValueError("not a sun-path Kalman state")
        cfg = KalmanConfig(**d["config"])
        site = Site(**d["site"]) if d.get("site") else None
        kf = cls(cfg, site)
        kf.mode = d["mode"]
        x = np.asarray(d["x"], dtype=float)
        P = np.asarray(d["P"], dtype=float)
        if x.shape != (6,) or P.shape != (6, 6) or not (np.all(np.isfinite(x))
                                                         and np.all(np.isfinite(P))):
            raise ValueError("state vector must have 6 finite values and P 6x6")
        if kf.mode == "free" and d.get("free_model") != FREE_MODEL:
            x, P = _free_state_from_dec_rate(x, P)  # state file from before the orbit model
        kf.ekf.x, kf.ekf.P = x, P
        kf.obliquity_applied = bool(d.get("obliquity_applied", False))
        kf.t = None if d["t"] is None else float(d["t"])
        kf.initialised = bool(d["initialised"])
        kf.buffer = [SunObservation(float(a), float(b), float(c), float(s))
                     for a, b, c, s in d.get("buffer", [])]
        kf.n_accepted = int(d.get("n_accepted", 0))
        kf.n_rejected = int(d.get("n_rejected", 0))
        return kf


def _free_state_from_dec_rate(x, P):
    """Convert an old ``free`` state (dec deg, rate deg/day) to the orbit's (u, v)."""
    x = x.copy()
    d, r = np.radians(x[DEC]), np.radians(x[RATE])
    n = np.radians(MEAN_MOTION_DEG_PER_DAY)
    J = np.eye(6)
    J[DEC, DEC] = np.cos(d) * np.pi / 180.0
    J[RATE, DEC] = -np.sin(d) * r / n * np.pi / 180.0
    J[RATE, RATE] = np.cos(d) / n * np.pi / 180.0
    x[DEC], x[RATE] = np.sin(d), np.cos(d) * r / n
    return x, J @ P @ J.T


def run_kalman(observations: list[SunObservation], config: KalmanConfig | None = None,
               site: Site | None = None, utc_offset_h: float | None = None,
               kf: SunPathKalman | None = None) -> tuple[list[DayResult], SunPathKalman]:
    """Run the filter over observations (any order) and summarise each local day.

    Each day's row is the filter's state after that day's last observation (a filtered,
    not smoothed, estimate); days before the filter could start give no row.
    """
    kf = kf or SunPathKalman(config, site)
    obs = sorted(observations, key=lambda o: o.time)
    times = np.array([o.time for o in obs])
    results = []
    for day in split_days(times, utc_offset_h):
        rej0 = kf.n_rejected
        for i in day.index:
            kf.update(obs[i])
        if kf.initialised:
            results.append(kf.day_result(float(np.median(times[day.index])), day.date,
                                         int(day.index.size), kf.n_rejected - rej0))
    return results, kf
