"""Starting the sun-path Kalman filter: a batch fit of the first observations.

Without a site the filter cannot linearise (latitude and longitude may be anywhere), so it
waits until ``init_min_obs`` observations span ``init_min_span_h`` hours, scores a coarse
grid of (latitude, longitude, declination) with the best constant azimuth offset, and runs
``scipy.optimize.least_squares`` (soft-L1) from the 4 best grid points.  It starts when
latitude and longitude are known to ``init_max_sigma_deg`` (one sigma), with the
covariance set to 4 times the fit's.  With a site, ``ephemeris`` mode starts at once and
``free`` mode after three observations half an hour apart (its declination comes from the
grid and the fit, never from SPA).

Angles in degrees (azimuth clockwise from north, ENU), times POSIX seconds (UTC).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize

from ..sun.source import Site
from ..sun.types import SunObservation
from .ephemeris import GeocentricSun, azel_from_hour_angle, geocentric_sun, wrap180
from .kalman_config import AZOFF, DEC, LAT, LON, RATE, REFR, KalmanConfig


@dataclass(frozen=True)
class InitialFit:
    """The filter's starting state from the batch fit.

    Attributes
    ----------
    x : ndarray, shape (6,)
        State (layout in :mod:`.kalman_config`).
    P : ndarray, shape (6, 6)
        Its covariance (symmetric).
    t : float
        POSIX seconds the state refers to: the last observation without a site, the first
        one with a site (the others are then assimilated one by one).
    n_used : int
        Observations the fit accepted (residual under 5 sigma).
    rms_sigma : float
        RMS residual per axis over every observation, in units of their sigma (about 1
        for a self-consistent sky; much more for garbage).
    """

    x: np.ndarray
    P: np.ndarray
    t: float
    n_used: int
    rms_sigma: float = float("nan")


def prior_mean_sigma(config: KalmanConfig, mode: str, site: Site | None) -> tuple[np.ndarray, np.ndarray]:
    """Prior mean and one-sigma of the state (for the batch fit) given what is known.

    ``ephemeris`` mode: the declination correction is 0 +- 0.05 deg and its drift
    0 +- 0.001 deg/day; a given site has ``config.site_sigma_deg``.
    """
    c = config
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    s0 = np.array([c.sigma_lat, c.sigma_lon, c.sigma_dec, c.sigma_rate, c.sigma_az_off, c.sigma_refr])
    if site is not None:
        x0[LAT], x0[LON] = site.latitude, site.longitude
        s0[LAT] = s0[LON] = c.site_sigma_deg
    if mode == "ephemeris":
        s0[DEC], s0[RATE] = 0.05, 1e-3  # correction to SPA's declination
    return x0, s0


def initial_fit(
    observations: list[SunObservation], config: KalmanConfig, mode: str, site: Site | None
) -> InitialFit | None:
    """Batch fit of the buffered observations, or None while they cannot start the filter.

    Parameters
    ----------
    observations : list of SunObservation
        Sensor-frame azimuth and elevation with one-sigma, sorted by time.
    config : KalmanConfig
    mode : {"free", "ephemeris"}
        Declination mode (``free``: the fitted declination becomes ``u = sin(dec)`` and
        ``v = 0 +- sin(eps)``, the direction of motion being unknown).
    site : Site or None
        Known site (latitude north-positive, longitude east-positive), or None.
    """
    obs = observations
    t = np.array([o.time for o in obs])
    c = config
    known = site is not None
    if not known:
        if len(obs) < c.init_min_obs or t[-1] - t[0] < c.init_min_span_h * 3600.0:
            return None
    elif mode == "free" and (len(obs) < 3 or t[-1] - t[0] < 1800.0):
        return None  # declination from the sky: a few observations half an hour apart
    t_ref = float(t[-1])
    geo = geocentric_sun(t)
    az = np.array([o.az_deg for o in obs])
    el = np.array([o.el_deg for o in obs])
    sig = np.array([o.sigma_deg for o in obs])
    x0, s0 = prior_mean_sigma(config, mode, site)
    free = [LAT, LON, AZOFF] + ([DEC] if mode == "free" else [])
    if known:
        free = [AZOFF] + ([DEC] if mode == "free" else [])

    def model(p, fixed, continuous=False):
        x = fixed.copy()
        x[free] = p
        h = wrap180(geo.sidereal_deg + x[LON] - geo.ra_deg)
        d = x[DEC] + (geo.dec_deg if mode == "ephemeris" else 0.0)
        m_az, m_el = azel_from_hour_angle(h, d, x[LAT], x[REFR], c.pressure_hpa, c.temp_c, continuous)
        return m_az + x[AZOFF], m_el

    def resid(p, fixed, continuous=False):
        m_az, m_el = model(p, fixed, continuous)
        r = np.concatenate([wrap180(az - m_az) * np.cos(np.radians(el)) / sig, (el - m_el) / sig])
        x = fixed.copy()
        x[free] = p
        pri = [(x[k] - x0[k]) / s0[k] for k in free if s0[k] < 1.0]
        return np.concatenate([r, pri])

    def jac(p, fixed):  # refraction without SPA's step: see central_jacobian
        return central_jacobian(lambda q: resid(q, fixed, True), p)

    fixed = x0.copy()
    starts = grid_starts(geo, az, el, fixed, free, known, config, mode)
    best = None
    for p in starts:
        sol = optimize.least_squares(resid, p, jac=jac, args=(fixed,), loss="soft_l1", f_scale=3.0)
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None  # grid_starts always gives at least one start
    J = best.jac
    n = len(obs)
    # Drop gross outliers before judging the fit.
    r = best.fun[: 2 * n].reshape(2, n)
    ok = np.hypot(r[0], r[1]) < 5.0
    try:
        cov = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return None
    x = fixed.copy()
    x[free] = best.x
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    fi = {k: i for i, k in enumerate(free)}
    if not known and (max(sd[fi[LAT]], sd[fi[LON]]) > c.init_max_sigma_deg or ok.mean() < 0.7):
        return None
    P = np.diag(s0**2)
    idx = np.array(free)
    P[np.ix_(idx, idx)] = cov * 4.0  # inflate: the batch fit ignored the rate and refr
    if mode == "free":
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
    return InitialFit(
        x, 0.5 * (P + P.T), t_ref if not known else float(t[0]), int(ok.sum()), float(np.sqrt(np.mean(r**2)))
    )


def central_jacobian(f, p: np.ndarray, step: float = 1e-5) -> np.ndarray:
    """Central-difference Jacobian of the vector function ``f`` at ``p`` (steps in deg).

    The fit differentiates its residuals with the refraction held continuous across SPA's
    0.616-deg step at the horizon (:func:`.ephemeris.refraction_deg`): scipy's own
    differences straddled the step whenever a model elevation sat on it (where the fit
    puts an observation that falls in the step's gap), a slope of 1e5 that made the
    latitude's one-sigma 5e-7 deg.
    """
    p = np.asarray(p, dtype=float)
    cols = []
    for k in range(p.size):
        dp = np.zeros_like(p)
        dp[k] = step
        cols.append((f(p + dp) - f(p - dp)) / (2.0 * step))
    return np.stack(cols, axis=1)


def grid_starts(
    geo: GeocentricSun,
    az: np.ndarray,
    el: np.ndarray,
    fixed: np.ndarray,
    free: list[int],
    known: bool,
    config: KalmanConfig,
    mode: str,
) -> list[np.ndarray]:
    """Starting points: a coarse grid scored with the best constant azimuth offset.

    The grid is latitude -75..75 deg by 7.5, longitude -180..170 by 10 and (``free``
    mode) declination -24..24 by 6; with a site only its latitude and longitude.  Each
    node gets the circular-mean azimuth offset and a cost clipped at 25 deg^2 per
    observation (robust to outliers); the 4 cheapest nodes are returned as vectors of the
    ``free`` state entries.
    """
    c = config
    lats = [fixed[LAT]] if known else np.arange(-75.0, 76.0, 7.5)
    lons = [fixed[LON]] if known else np.arange(-180.0, 180.0, 10.0)
    decs = [fixed[DEC]] if mode == "ephemeris" else np.arange(-24.0, 24.1, 6.0)
    L, G, D = np.meshgrid(lats, lons, decs, indexing="ij")
    L, G, D = L.ravel()[:, None], G.ravel()[:, None], D.ravel()[:, None]
    h = wrap180(geo.sidereal_deg[None, :] + G - geo.ra_deg[None, :])
    d = D + (geo.dec_deg[None, :] if mode == "ephemeris" else 0.0)
    m_az, m_el = azel_from_hour_angle(h, d, L, 1.0, c.pressure_hpa, c.temp_c)
    daz = np.radians(az[None, :] - m_az)
    off = np.degrees(np.arctan2(np.sin(daz).mean(1), np.cos(daz).mean(1)))
    raz = wrap180(az[None, :] - m_az - off[:, None]) * np.cos(np.radians(el))[None, :]
    cost = np.sum(np.minimum(raz**2 + (el[None, :] - m_el) ** 2, 25.0), axis=1)
    order = np.argsort(cost)[:4]
    starts = []
    for j in order:
        x = fixed.copy()
        x[LAT], x[LON], x[AZOFF] = L[j, 0], G[j, 0], off[j] % 360.0
        if DEC in free:
            x[DEC] = D[j, 0]
        starts.append(x[free])
    return starts
