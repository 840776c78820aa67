"""Records of the sun-path Kalman filter: its state layout, tuning and outputs.

State vector (degrees unless stated; index constants below)::

    LAT    site latitude, north-positive
    LON    site longitude, east-positive (equivalently the noon offset: 1 deg = 240 s)
    DEC    ``free``: u = sin(eps) sin(lambda) = sin(declination) (dimensionless);
           ``ephemeris``: a correction (deg) added to SPA's geocentric declination
    RATE   ``free``: v = sin(eps) cos(lambda) (dimensionless); ``ephemeris``: the
           correction's daily drift, deg/day
    AZOFF  sensor azimuth minus true azimuth (deg, clockwise from north)
    REFR   refraction scale (1 = SPA's standard atmosphere)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .orbit import OBLIQUITY_DEG

LAT, LON, DEC, RATE, AZOFF, REFR = range(6)
STATE_NAMES = ("lat_deg", "lon_deg", "dec_deg", "dec_rate_deg_per_day", "az_offset_deg", "refraction_scale")
STATE_NAMES_FREE = ("lat_deg", "lon_deg", "orbit_u_sin_dec", "orbit_v", "az_offset_deg", "refraction_scale")
#: Version tag of the ``free`` mode's declination states (u, v); older state files held
#: (declination deg, rate deg/day) and are converted on load.
FREE_MODEL = "orbit-uv-1"
#: Declination modes of :class:`KalmanConfig`.
DECLINATION_MODES = ("free", "ephemeris")


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
        After this many gated observations in a row (and every as many more), the run of
        rejected observations is tried as a new start (see ``reinit_max_rms``); failing
        that, the covariance is inflated (one-sigma x5 at most, never past
        ``max_inflation_sigma_deg``), so a filter that has drifted cannot lock itself out
        and garbage cannot blow it up.
    max_inflation_sigma_deg : float
        Inflation never widens an angle's one-sigma past this, deg (latitude and longitude
        without a site; with one, they stay at ``site_sigma_deg``).
    reinit_max_rms : float
        A run of rejected observations restarts the filter only when the batch fit on it
        alone has an RMS residual (per axis, in units of the observations' sigma) at most
        this: a self-consistent sky, not garbage.
    max_consecutive_older : int
        Observations older than the state are rejected and counted; this many in a row,
        in time order among themselves and spanning ``rebase_min_span_s``, mean the clock
        stepped back: the state is carried back to them (re-based) and they are used.
    rebase_min_span_s : float
        The least time such a run must span, s.
    site_mismatch_deg : float
        With a site given, a self-consistent sky that puts the site further than this from
        it is reported (``site_mismatch``), not followed.
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
    max_inflation_sigma_deg: float = 2.0
    reinit_max_rms: float = 2.0
    max_consecutive_older: int = 6
    rebase_min_span_s: float = 1800.0
    site_mismatch_deg: float = 1.0
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
    """What the filter did with one observation.

    Attributes
    ----------
    accepted : bool
        The observation moved the state (or started the filter).
    mahalanobis2 : float
        Squared Mahalanobis distance of the innovation (2 dof); nan when not computed.
    initialised : bool
        Whether the filter had started after this observation.
    reason : str
        Why it was not used (``"gated"``, ``"waiting to initialise"``, ...), or
        ``"initialised"``.
    """

    accepted: bool
    mahalanobis2: float
    initialised: bool
    reason: str = ""


@dataclass(frozen=True)
class Prediction:
    """Predicted true sun direction (ENU) with the covariance of (azimuth, elevation).

    Attributes
    ----------
    time : float
        POSIX seconds (UTC).
    az_deg, el_deg : float
        Azimuth clockwise from north and apparent elevation, deg.
    covariance : ndarray, shape (2, 2)
        Covariance of (azimuth, elevation), deg^2 (azimuth not scaled by cos(el)).
    """

    time: float
    az_deg: float
    el_deg: float
    covariance: np.ndarray = field(repr=False)

    @property
    def sigma_deg(self) -> float:
        """Total one-sigma angle on the sky, deg (azimuth scaled by cos(el))."""
        c = np.cos(np.radians(self.el_deg))
        return float(np.sqrt(max(self.covariance[0, 0] * c * c + self.covariance[1, 1], 0.0)))
