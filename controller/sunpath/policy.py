"""Choosing the controller's sun estimate: observed, predicted or ephemeris.

:class:`SunPathSource` feeds sensor observations to the sun-path filter and answers
``estimate(t)`` with a :class:`~controller.sun.types.SunEstimate` whose ``source`` says
what it rests on, so every setpoint built from it records that source:

* ``observed``  - the filter's posterior when an observation it accepted is at most
  ``max_obs_age_s`` old (before the filter has started: the raw observation itself);
* ``predicted`` - the filter's prediction through a cloud gap (or after a rejected
  observation), while its one-sigma is below ``max_predicted_sigma_deg``;
* ``ephemeris`` - SPA for a known site when it is more certain than the prediction, or
  when nothing else is available.

Prediction and ephemeris are blended by inverse covariance in the sky's tangent plane.
Because an accepted observation only moves the filter by its Kalman gain, the estimate
changes smoothly when the sun disappears and reappears: there is no switch to a raw,
noisy measurement.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..sun.source import EphemerisSource, Site, SunSource
from ..sun.types import EstimateSource, SunEstimate, SunObservation
from .kalman import KalmanConfig, SunPathKalman


@dataclass(frozen=True)
class PolicyConfig:
    """Thresholds of the estimate policy.

    Attributes
    ----------
    max_obs_age_s : float
        An accepted observation counts as "the sun is seen" for this long, s.
    max_predicted_sigma_deg : float
        A prediction less certain than this (one-sigma, deg) is not used.
    """

    max_obs_age_s: float = 120.0
    max_predicted_sigma_deg: float = 2.0


def fuse(estimates: list[SunEstimate], source: EstimateSource, t: float) -> SunEstimate:
    """Inverse-covariance blend of estimates of the same instant.

    Works in the tangent plane ``(az cos(el), el)`` around the first estimate, so it is
    fine across north (azimuth 0/360).  Returns the blended direction and covariance.
    """
    ref_az, ref_el = estimates[0].az_deg, estimates[0].el_deg
    c = np.cos(np.radians(ref_el))
    info = np.zeros((2, 2))
    vec = np.zeros(2)
    for e in estimates:
        d = np.array([((e.az_deg - ref_az + 180.0) % 360.0 - 180.0) * c, e.el_deg - ref_el])
        cov = np.diag([c, 1.0]) @ e.covariance @ np.diag([c, 1.0])
        W = np.linalg.inv(cov + np.eye(2) * 1e-12)
        info += W
        vec += W @ d
    cov_t = np.linalg.inv(info)
    d = cov_t @ vec
    cs = max(c, 1e-6)
    az = (ref_az + d[0] / cs) % 360.0
    el = ref_el + d[1]
    cov = np.diag([1 / cs, 1.0]) @ cov_t @ np.diag([1 / cs, 1.0])
    return SunEstimate(float(t), float(az), float(el), cov, source)


def select_estimate(t: float, fresh_observation: SunObservation | None,
                    prediction: SunEstimate | None, ephemeris: SunEstimate | None,
                    config: PolicyConfig = PolicyConfig(), now: float | None = None
                    ) -> SunEstimate | None:
    """The policy as a pure function (see module docstring).

    ``prediction`` is the filter's estimate at ``t`` (already including any accepted
    observation); ``fresh_observation`` is the last accepted one, or None.  ``now`` is
    the present when ``t`` lies ahead (a setpoint aimed at mid-period): an observation's
    freshness is judged against the present, not against the aim time.
    """
    if prediction is not None and prediction.sigma_deg > config.max_predicted_sigma_deg:
        prediction = None
    fresh = (fresh_observation is not None
             and 0.0 <= (t if now is None else now) - fresh_observation.time
             <= config.max_obs_age_s)
    if prediction is not None:
        if fresh:
            return SunEstimate(t, prediction.az_deg, prediction.el_deg, prediction.covariance,
                               EstimateSource.OBSERVED)
        if ephemeris is None:
            return SunEstimate(t, prediction.az_deg, prediction.el_deg, prediction.covariance,
                               EstimateSource.PREDICTED)
        dominant = (EstimateSource.EPHEMERIS if ephemeris.sigma_deg < prediction.sigma_deg
                    else EstimateSource.PREDICTED)
        return fuse([prediction, ephemeris], dominant, t)
    if fresh:
        o = fresh_observation
        s2 = o.sigma_deg ** 2
        c = max(np.cos(np.radians(o.el_deg)), 1e-6)
        return SunEstimate(t, o.az_deg, o.el_deg, np.diag([s2 / (c * c), s2]),
                           EstimateSource.OBSERVED)
    return ephemeris


class SunPathSource(SunSource):
    """Sun source backed by the sun-path filter, with ephemeris fallback and persistence.

    Parameters
    ----------
    site : Site, optional
        Known site: seeds the filter and enables the ephemeris fallback.
    state_path : path, optional
        Learned state is loaded from here at start (if the file exists) and written by
        :meth:`save`.  A corrupt file raises :class:`~controller.sunpath.state.StateError`.
    kalman_config, policy_config : optional tuning.
    """

    name = "sunpath"

    def __init__(self, site: Site | None = None, state_path: str | Path | None = None,
                 kalman_config: KalmanConfig | None = None,
                 policy_config: PolicyConfig | None = None):
        from .state import load_state

        self.site = site
        self.state_path = Path(state_path) if state_path is not None else None
        self.policy = policy_config or PolicyConfig()
        self.kf = load_state(self.state_path) if self.state_path is not None else None
        if self.kf is None:
            self.kf = SunPathKalman(kalman_config, site)
        self.ephemeris = EphemerisSource(site) if site is not None else None
        self.last_accepted: SunObservation | None = None

    def observe(self, obs: SunObservation) -> bool:
        """Give the filter one observation (ENU or sensor frame); True when accepted."""
        res = self.kf.update(obs)
        if res.accepted or not self.kf.initialised:  # buffered for the filter's start
            self.last_accepted = obs
        return res.accepted

    def prediction(self, t: float) -> SunEstimate | None:
        """The filter's estimate at ``t`` as a PREDICTED SunEstimate (None before start)."""
        if not self.kf.initialised:
            return None
        p = self.kf.predict(t)
        return SunEstimate(float(t), p.az_deg, p.el_deg, p.covariance,
                           EstimateSource.PREDICTED)

    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        eph = self.ephemeris.estimate(t) if self.ephemeris is not None else None
        obs = self.last_accepted
        if obs is not None and not self.kf.initialised:
            # before the filter starts, a raw sensor azimuth is only usable in ENU
            obs = obs if obs.frame == "enu" else None
        return select_estimate(float(t), obs, self.prediction(t), eph, self.policy, now=now)

    def save(self) -> None:
        """Persist the learned state atomically (no-op without ``state_path``)."""
        from .state import save_state

        if self.state_path is not None:
            save_state(self.state_path, self.kf)

