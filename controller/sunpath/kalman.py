"""A physical sun-path model in an extended Kalman filter (filterpy).

The state vector (latitude, longitude, declination state, its rate, azimuth offset,
refraction scale) and the filter's records are in :mod:`.kalman_config`; the orbit law in
:mod:`.orbit`; the batch fit that starts the filter in :mod:`.initial_fit`; the JSON
snapshot in :mod:`.persistence`.  This module is the EKF itself.

The measurement model ``h(x, t)`` is spherical astronomy: the hour angle is SPA's apparent
sidereal time plus ``lon`` minus the sun's right ascension (i.e. UTC, longitude and the
equation of time), and azimuth and elevation follow from hour angle, declination and
latitude (:func:`~controller.sunpath.ephemeris.azel_from_hour_angle`).  The innovation is
expressed in the sky's tangent plane, ``(d_az cos(el), d_el)``, so it stays well defined
near the zenith and one isotropic sigma describes the sensor.  The Jacobian is numeric.

In ``free`` mode (sky only: declination from the observations alone) the declination
follows the law of the sun's orbit, ``sin(dec) = sin(eps) sin(lambda)``: the state holds
the vector ``(u, v) = sin(eps) (sin lambda, cos lambda)``, whose length is ``sin(eps)`` (obliquity)
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
(``free`` mode, whose declination comes from a grid and a fit, not from the ephemeris).
Process noise is continuous in time, so a night or a cloudy week widens the covariance by
the right amount and the state carries over.
"""

from __future__ import annotations

import copy

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from ..sun.source import Site
from ..sun.types import SunObservation
from .bounds import bound_covariance, max_sigma, observation_problem, state_problem
from .days import DayResult
from .ephemeris import GeocentricSun, azel_from_hour_angle, geocentric_sun, transit_time, wrap180
from .initial_fit import initial_fit
from .kalman_config import (
    AZOFF,
    DEC,
    DECLINATION_MODES,
    FREE_MODEL,
    LAT,
    LON,
    RATE,
    REFR,
    STATE_NAMES,
    STATE_NAMES_FREE,
    KalmanConfig,
    Prediction,
    UpdateResult,
)
from .orbit import (
    DAY_S,
    MEAN_MOTION_DEG_PER_DAY,
    OBLIQUITY_DEG,
    OMEGA_YEAR,
    orbit_advance_deg,
    orbit_rotation,
)
from .persistence import kalman_from_dict, kalman_to_dict
from .recovery import SiteMismatch, add_older, add_to_run, assess_run, inflate, inflation_caps

# Callers import the filter's records and the orbit law from here too.
__all__ = [
    "AZOFF",
    "DEC",
    "FREE_MODEL",
    "LAT",
    "LON",
    "MEAN_MOTION_DEG_PER_DAY",
    "OBLIQUITY_DEG",
    "OMEGA_YEAR",
    "RATE",
    "REFR",
    "STATE_NAMES",
    "STATE_NAMES_FREE",
    "KalmanConfig",
    "Prediction",
    "SunPathKalman",
    "UpdateResult",
    "orbit_advance_deg",
]


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
        if mode not in DECLINATION_MODES:
            raise ValueError(f"declination mode must be 'free' or 'ephemeris', got {mode!r}")
        self.mode = mode
        self.ekf = ExtendedKalmanFilter(dim_x=6, dim_z=2)
        self.t: float | None = None  # time the state refers to
        self.initialised = False
        self.buffer: list[SunObservation] = []
        self.consecutive_rejects = 0
        self.n_accepted = 0
        self.n_rejected = 0  # every observation not used, whatever the reason
        self.n_older = 0  # of which: older than the state
        self.n_invalid = 0  # of which: not an observation of the sun (NaN, el > 90, ...)
        self.n_reinit = 0  # restarts from a self-consistent run of rejections
        self.n_rebase = 0  # states carried back to a clock that stepped back
        self.obliquity_applied = False
        # Transient (not saved): the runs :mod:`.recovery` judges, and what it found.
        self.rejected_run: list[SunObservation] = []
        self.older_run: list[SunObservation] = []
        self.site_mismatch: SiteMismatch | None = None
        self._run_judged_at = float("nan")  # last run member judged (judge once per member)
        self._consecutive_accepts = 0

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

    def _azel(self, x, geo: GeocentricSun, i=0, continuous=False):
        """Model (sensor azimuth, elevation) for state ``x`` at the time of ``geo[i]``
        (``continuous``: refraction without SPA's step, for derivatives only)."""
        h = wrap180(geo.sidereal_deg[i] + x[LON] - geo.ra_deg[i])
        c = self.config
        az, el = azel_from_hour_angle(
            h, self._dec(x, geo, i), x[LAT], x[REFR], c.pressure_hpa, c.temp_c, continuous
        )
        return float(az) + x[AZOFF], float(el)

    def _jacobian(self, x, geo, i=0, scaled=True):
        """Numeric Jacobian of ``(az cos(el), el)`` (``scaled``) or ``(az, el)`` w.r.t. x.

        The geometry's columns ignore SPA's refraction step at the horizon (a difference
        across it was a slope of 3000); the refraction scale's column is SPA's own.
        """
        _, el0 = self._azel(x, geo, i)
        c = np.cos(np.radians(el0)) if scaled else 1.0
        J = np.zeros((2, 6))
        for k, step in enumerate((1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4)):
            xp, xm = x.copy(), x.copy()
            xp[k] += step
            xm[k] -= step
            smooth = k != REFR
            azp, elp = self._azel(xp, geo, i, smooth)
            azm, elm = self._azel(xm, geo, i, smooth)
            J[0, k] = float(wrap180(azp - azm)) / (2 * step) * c
            J[1, k] = (elp - elm) / (2 * step)
        return J

    @staticmethod
    def _residual(z, hx):
        """Tangent-plane residual ``(d_az cos(el), d_el)`` in deg."""
        return np.array([float(wrap180(z[0] - hx[0])) * np.cos(np.radians(hx[1])), z[1] - hx[1]])

    # ------------------------------------------------------------------ time update
    def _transition(self, t0: float, t1: float):
        """Transition matrix and process noise from POSIX ``t0`` to ``t1``."""
        d = (t1 - t0) / DAY_S
        ad = abs(d)
        F = np.eye(6)
        c = self.config
        Q = np.zeros((6, 6))
        if self.mode == "free":  # rotate (u, v) by the advance of the ecliptic longitude
            cos_th, sin_th = orbit_rotation(t0, t1, c.orbit_rate)
            F[DEC, DEC] = F[RATE, RATE] = cos_th
            F[DEC, RATE] = sin_th
            F[RATE, DEC] = -sin_th
            Q[DEC, DEC] = Q[RATE, RATE] = c.q_orbit * ad
        else:  # correction to SPA: constant plus slow drift
            F[DEC, RATE] = d
            qr = c.q_rate_ephemeris
            Q[DEC, DEC] = c.q_dec * ad + qr * ad**3 / 3
            Q[DEC, RATE] = Q[RATE, DEC] = qr * d * ad / 2  # sign of d: also backwards
            Q[RATE, RATE] = qr * ad
        Q[LAT, LAT] = Q[LON, LON] = c.q_site * ad
        Q[AZOFF, AZOFF] = c.q_az_off * ad
        Q[REFR, REFR] = c.q_refr * ad
        return F, Q

    def _state_time(self) -> float:
        """Time the state refers to (POSIX s); RuntimeError before the filter has started."""
        if self.t is None:
            raise RuntimeError("the sun-path filter has not been initialised yet")
        return self.t

    def _propagate(self, t: float) -> None:
        F, Q = self._transition(self._state_time(), float(t))
        self.ekf.F, self.ekf.Q = F, Q
        self.ekf.predict()
        # years without an observation must not leave a variance that means nothing
        self.ekf.P = bound_covariance(self.ekf.P, max_sigma(self.mode))
        self.t = float(t)

    def _propagated(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        F, Q = self._transition(self._state_time(), float(t))
        return F @ self.ekf.x, F @ self.ekf.P @ F.T + Q

    def _apply_obliquity(self) -> None:
        """``free`` mode: the obliquity as one pseudo-observation of ``|(u, v)|``.

        Applied once, when the data have told the sign of ``v`` (sun moving north or
        south) at three sigma; the rotation keeps the vector's length, so the information
        is kept afterwards (apart from the small process noise).
        """
        c = self.config
        if self.mode != "free" or self.obliquity_applied or c.obliquity_sigma_deg <= 0:
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
        """Assimilate one observation (sensor-frame azimuth, elevation, sigma).

        An observation that is not one of the sun, one older than the state and one the
        innovation gate refuses are rejected and counted; an update that would leave the
        state unphysical (:func:`.bounds.state_problem`) is refused likewise.  Runs of
        them are handled by :mod:`.recovery`.
        """
        bad = observation_problem(obs)
        if bad is not None:
            self.n_invalid += 1
            self.n_rejected += 1
            return UpdateResult(False, float("nan"), self.initialised, f"invalid observation: {bad}")
        if not self.initialised:
            self.buffer.append(obs)
            if self._try_initialise():
                return UpdateResult(True, 0.0, True, "initialised")
            return UpdateResult(False, float("nan"), False, "waiting to initialise")
        if obs.time < self._state_time() - 1e-6:
            return self._older(obs)
        self.older_run = []
        self._propagate(obs.time)
        geo = geocentric_sun(obs.time)
        z = np.array([obs.az_deg, obs.el_deg])
        R = np.eye(2) * obs.sigma_deg**2
        H = self._jacobian(self.ekf.x, geo)
        y = self._residual(z, self._azel(self.ekf.x, geo))
        S = H @ self.ekf.P @ H.T + R
        d2 = float(y @ np.linalg.solve(S, y))
        if not d2 <= self.config.gate_chi2:  # also NaN
            return self._rejected(obs, d2, "gated")
        x0, P0, obliquity0 = self.ekf.x.copy(), self.ekf.P.copy(), self.obliquity_applied
        if self.config.iterations <= 1:
            self.ekf.update(
                z,
                lambda x: self._jacobian(x, geo),
                lambda x: np.array(self._azel(x, geo)),
                R=R,
                residual=self._residual,
            )
        else:
            self._iterated_update(z, R, geo, H, y)
        self._normalise()
        self._apply_obliquity()
        bad_state = state_problem(self.ekf.x, self.ekf.P, self.mode)
        if bad_state is not None:  # keep the prior: the linearisation failed, not the sky
            self.ekf.x, self.ekf.P, self.obliquity_applied = x0, P0, obliquity0
            return self._rejected(obs, d2, "non-physical update ({}: {})".format(*bad_state))
        self.consecutive_rejects = 0
        self.rejected_run = []
        self._consecutive_accepts += 1
        if self._consecutive_accepts >= self.config.max_consecutive_rejects:
            self.site_mismatch = None  # the sky agrees with the state again
        self.n_accepted += 1
        return UpdateResult(True, d2, True)

    def _rejected(self, obs: SunObservation, d2: float, reason: str) -> UpdateResult:
        """Count a rejection and, every ``max_consecutive_rejects`` in a row, recover."""
        c = self.config
        self.consecutive_rejects += 1
        self.n_rejected += 1
        self._consecutive_accepts = 0
        add_to_run(self.rejected_run, obs, c)
        if self.consecutive_rejects % c.max_consecutive_rejects:
            return UpdateResult(False, d2, True, reason)
        run = self.rejected_run
        verdict = None
        if run and run[-1].time != self._run_judged_at:
            self._run_judged_at = run[-1].time
            verdict = assess_run(run, c, self.mode, self.site)
        if verdict is not None and verdict.action == "restart" and verdict.fit is not None:
            self._restart(verdict.fit, run if verdict.site_fixed else [])
            return UpdateResult(True, d2, True, "re-initialised from the rejected run")
        if verdict is not None and verdict.mismatch is not None:
            self.site_mismatch = verdict.mismatch
        if self.consecutive_rejects == c.max_consecutive_rejects:
            # The filter may have drifted just past the gate: widen once per run, boundedly.
            # A run that goes on is judged as a whole instead (above): widening again would
            # only let garbage in.
            self.ekf.P = inflate(self.ekf.P, inflation_caps(c, self.mode, self.site))
        return UpdateResult(False, d2, True, reason)

    def _restart(self, fit, run: list[SunObservation]) -> None:
        """Start again from ``fit``; with a site fixed, assimilate the rest of ``run``."""
        self.ekf.x, self.ekf.P, self.t = fit.x.copy(), fit.P.copy(), fit.t
        self.obliquity_applied = False
        self.consecutive_rejects = 0
        self.rejected_run = []
        self.n_reinit += 1
        for o in sorted(run, key=lambda o: o.time)[1:]:
            self.update(o)

    def _older(self, obs: SunObservation) -> UpdateResult:
        """Reject (and count) an observation older than the state; re-base on a clock step."""
        self.n_older += 1
        self.n_rejected += 1
        if not add_older(self.older_run, obs, self.config):
            return UpdateResult(False, float("nan"), True, "older than the state")
        run, self.older_run = self.older_run, []
        self.n_rebase += 1
        self._propagate(run[0].time)  # carried back: process noise of the whole step
        for o in run:
            res = self.update(o)
        return UpdateResult(res.accepted, res.mahalanobis2, True, f"re-based; {res.reason}")

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
    def _try_initialise(self) -> bool:
        """Start from the batch fit of the buffer (:mod:`.initial_fit`) once it can."""
        obs = sorted(self.buffer, key=lambda o: o.time)
        fit = initial_fit(obs, self.config, self.mode, self.site)
        if fit is None or state_problem(fit.x, fit.P, self.mode) is not None:
            return False
        self.ekf.x = fit.x
        self.ekf.P = fit.P
        self.t = fit.t
        self.initialised = True
        self.buffer = []
        if self.site is not None:
            # the site gave the geometry: now assimilate every buffered observation
            self.n_accepted += 1  # the first one started the filter
            for o in obs[1:]:
                self.update(o)
        else:
            self.n_accepted += fit.n_used
        return True

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
            date=date,
            noon_utc=tn,
            noon_el_deg=self.predict(tn).el_deg,
            declination_deg=dec,
            lat_deg=float(x[LAT]),
            lon_deg=float(wrap180(x[LON])),
            n_obs=n_obs,
            method="kalman",
            az_offset_deg=float(x[AZOFF] % 360.0),
            n_rejected=n_rejected,
            noon_sigma_s=sn,
            lat_sigma_deg=float(np.sqrt(P[LAT, LAT])),
            lon_sigma_deg=float(np.sqrt(P[LON, LON])),
            dec_sigma_deg=sdec,
        )

    def copy(self) -> SunPathKalman:
        """Independent deep copy (e.g. to predict from a checkpoint)."""
        return copy.deepcopy(self)

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict:
        """JSON-ready snapshot (:func:`.persistence.kalman_to_dict`, :mod:`.state`)."""
        return kalman_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict, now: float | None = None) -> SunPathKalman:
        """Inverse of :meth:`to_dict`, validated (:func:`.persistence.kalman_from_dict`).

        Raises :class:`~controller.sunpath.persistence.SnapshotError` (a ValueError) naming
        the field when the snapshot is malformed, not physical or not plausible.
        """
        return kalman_from_dict(d, cls, now=now)
