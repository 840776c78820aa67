"""How the sun-path filter recovers: from a run of rejections, and from a clock step back.

A gated observation is either a bad observation (a reflection, a cloud edge) or a sign
that the filter, not the sky, is wrong.  One observation cannot tell; a run of them can:

* **A run of rejections** (``max_consecutive_rejects`` in a row, then every as many more).
  The run alone is fitted from scratch (:func:`.initial_fit.initial_fit`).  When that fit
  is *self-consistent* (RMS residual per axis at most ``reinit_max_rms`` times the
  observations' sigma, and a physical state), the sky is coherent and the filter is
  wrong: it restarts from the fit.  Otherwise the run is garbage: the state is kept, the
  observations stay rejected, and the covariance is widened by a bounded factor (one-sigma
  x5 at most and never past :func:`inflation_caps`), so a filter that drifted slightly can
  still re-acquire while garbage cannot blow it up.  Repeated x25 inflation without a
  bound used to let a wide covariance accept anything: latitude 412 deg after a one-hour
  step in the observation times.
* **With a site given**, the run is first fitted with the site fixed (a sensor knocked
  round in azimuth: restart, site kept).  If only a fit with a free site is consistent and
  that site is more than ``site_mismatch_deg`` from the given one, it is *not* followed:
  the filter keeps the configured site as its prior and reports the offset
  (:class:`SiteMismatch`), for the loop to alarm.  A clock that is an hour off looks
  exactly like a site 15 deg away in longitude: from the sky alone a clock error is a
  longitude error, and only the configured site can tell them apart.
* **Observations older than the state** (a wall clock stepped back) are rejected and
  counted.  ``max_consecutive_older`` of them in a row, in time order among themselves and
  spanning ``rebase_min_span_s`` (a running clock, not a few reordered frames), mean the
  clock stepped back for good: the state is carried back to the first of them (the
  process noise grows with the step, whichever its sign) and they are assimilated.  A
  short step back (less than the span) resolves itself once the clock passes the state.

Angles in degrees, times in POSIX seconds (UTC).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sun.source import Site
from ..sun.types import SunObservation
from .bounds import state_problem
from .ephemeris import wrap180
from .initial_fit import InitialFit, initial_fit, prior_mean_sigma
from .kalman_config import DEC, LAT, LON, RATE, REFR, KalmanConfig

#: Largest one-sigma growth of one inflation step (variance x25, as before the bound).
INFLATION_STEP = 5.0
#: Least time a site-fixed restart's run must span, s (as the ``free`` mode's start).
SITE_RUN_MIN_SPAN_S = 1800.0


@dataclass(frozen=True)
class SiteMismatch:
    """A self-consistent sky puts the site this far from the given one.

    Attributes
    ----------
    lat_offset_deg, lon_offset_deg : float
        Sky's site minus the given site, deg (longitude wrapped to [-180, 180)).
    time : float
        POSIX s of the last observation of the run that showed it.
    """

    lat_offset_deg: float
    lon_offset_deg: float
    time: float

    def likely_cause(self, site: Site, tol_deg: float = 1.0) -> str:
        """The mistake that would make this offset from ``site``, as a phrase.

        A latitude's sign when the sky's latitude is the given one negated, a longitude's
        sign likewise, and time stamps in another zone when the rest of the longitude's
        offset is a whole or half number of hours (within ``tol_deg / 2``; 15 deg an hour,
        the stamps reading ``-lon_offset / 15`` h from UTC, or 24 h less or more); else all
        three to check.
        """
        lat, lon = site.latitude, site.longitude
        sky_lat = lat + self.lat_offset_deg
        sky_lon = float(wrap180(lon + self.lon_offset_deg))
        lat_off = abs(self.lat_offset_deg) > tol_deg
        causes = []
        if lat_off and abs(sky_lat + lat) <= tol_deg:
            causes.append(f"the latitude's sign (the sky's is {sky_lat:+.2f}: north is positive)")
        if abs(self.lon_offset_deg) > tol_deg:
            hours = -self.lon_offset_deg / 15.0
            zone = round(2.0 * hours) / 2.0
            if abs(float(wrap180(sky_lon + lon))) <= tol_deg:
                causes.append(f"the longitude's sign (the sky's is {sky_lon:+.2f}: east is positive)")
            elif (causes or not lat_off) and abs(hours - zone) * 15.0 <= tol_deg / 2.0:
                reads = " or ".join(f"{h:+g} h" for h in (zone, zone - 24, zone + 24) if -12 <= h <= 14)
                causes.append(
                    f"the time stamps' zone (they read {reads} from UTC: local times written "
                    "without their offset, or with the wrong one)"
                )
        if not causes:
            return "check the latitude's and the longitude's signs (north and east positive) and the time stamps' zone"
        return "likely " + ", and ".join(causes)


@dataclass(frozen=True)
class RunVerdict:
    """What a run of rejected observations says.

    Attributes
    ----------
    action : str
        ``"restart"`` (self-consistent: start again from ``fit``), ``"mismatch"`` (self-
        consistent only with a site far from the given one), ``"inconsistent"`` (garbage,
        or too short to judge).
    fit : InitialFit or None
        The fit to restart from.
    site_fixed : bool
        ``fit`` was made with the given site fixed (its observations after the first must
        then be assimilated one by one, as at a first start).
    mismatch : SiteMismatch or None
    """

    action: str
    fit: InitialFit | None = None
    site_fixed: bool = False
    mismatch: SiteMismatch | None = None


def inflation_caps(config: KalmanConfig, mode: str, site: Site | None) -> np.ndarray:
    """The one-sigma that inflation never exceeds, per state entry.

    The prior of each entry (:func:`.initial_fit.prior_mean_sigma`: a given site's
    ``site_sigma_deg``, SPA's declination correction) but no more than
    ``max_inflation_sigma_deg`` for an angle (radians of it for ``free`` mode's ``u, v``).
    """
    _, s0 = prior_mean_sigma(config, mode, site)
    m = config.max_inflation_sigma_deg
    caps = np.minimum(s0, m)
    if mode == "free":
        caps[DEC] = caps[RATE] = np.radians(m)
    caps[REFR] = min(s0[REFR], m)
    return caps


def inflate(P: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """``D P D`` with each one-sigma grown by up to :data:`INFLATION_STEP`, never past its cap.

    An entry already at or past its cap is not grown (nor shrunk); correlations are kept.
    """
    s = np.sqrt(np.clip(np.diag(P), 1e-300, None))
    d = np.clip(caps / s, 1.0, INFLATION_STEP)
    return P * np.outer(d, d)


def add_to_run(run: list[SunObservation], obs: SunObservation, config: KalmanConfig) -> bool:
    """Keep ``obs`` in the run of rejections if it thins the run to a useful sampling.

    The run keeps observations at least half the start's sampling apart
    (``init_min_span_h / init_min_obs / 2``: 7.5 min by default) and at most
    ``4 init_min_obs`` of them (the oldest go), so frames every second still give a run
    that spans hours.  Returns whether ``obs`` was kept.
    """
    spacing = 0.5 * config.init_min_span_h * 3600.0 / max(config.init_min_obs, 1)
    if run and obs.time - run[-1].time < spacing:
        return False
    run.append(obs)
    del run[: -4 * max(config.init_min_obs, 1)]
    return True


def _consistent(fit: InitialFit | None, config: KalmanConfig, mode: str) -> bool:
    return (
        fit is not None
        and fit.rms_sigma <= config.reinit_max_rms
        and state_problem(fit.x, fit.P, mode) is None
    )


def assess_run(run: list[SunObservation], config: KalmanConfig, mode: str, site: Site | None) -> RunVerdict:
    """Judge a run of rejected observations (see the module docstring).

    A run is judged only with as much evidence as a first start: with a site fixed,
    ``max_consecutive_rejects`` observations over half an hour; with a free site,
    ``init_min_obs`` over ``init_min_span_h`` hours.
    """
    c = config
    obs = sorted(run, key=lambda o: o.time)
    span = obs[-1].time - obs[0].time if obs else 0.0
    if site is not None and len(obs) >= c.max_consecutive_rejects and span >= SITE_RUN_MIN_SPAN_S:
        fit = initial_fit(obs, c, mode, site)
        if fit is not None and _consistent(fit, c, mode):
            return RunVerdict("restart", fit, site_fixed=True)
    if len(obs) < c.init_min_obs or span < c.init_min_span_h * 3600.0:
        return RunVerdict("inconsistent")
    fit = initial_fit(obs, c, mode, None)
    if fit is None or not _consistent(fit, c, mode):
        return RunVerdict("inconsistent")
    if site is None:
        return RunVerdict("restart", fit)
    dlat = float(fit.x[LAT] - site.latitude)
    dlon = float(wrap180(fit.x[LON] - site.longitude))
    if max(abs(dlat), abs(dlon)) > c.site_mismatch_deg:
        return RunVerdict("mismatch", mismatch=SiteMismatch(dlat, dlon, obs[-1].time))
    return RunVerdict("restart", fit)  # a site learned within a degree of the given one


def add_older(run: list[SunObservation], obs: SunObservation, config: KalmanConfig) -> bool:
    """Add an observation older than the state to the run of such; True: re-base now.

    The run holds observations in time order among themselves (one out of order starts
    it again).  It calls for a re-base when it has ``max_consecutive_older`` of them
    spanning at least ``rebase_min_span_s``.
    """
    if run and obs.time <= run[-1].time:
        run.clear()
    run.append(obs)
    return len(run) >= config.max_consecutive_older and run[-1].time - run[0].time >= config.rebase_min_span_s
