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

import logging
import re
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..store import Store, StoreError
from ..sun.source import EphemerisSource, Site, SunSource
from ..sun.types import EstimateSource, SunEstimate, SunObservation, azel_to_enu, enu_to_azel
from .ephemeris import wrap180
from .kalman import SunPathKalman
from .kalman_config import AZOFF, LAT, LON, KalmanConfig

log = logging.getLogger("heliotrack.sunpath")


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


def select_estimate(
    t: float,
    fresh_observation: SunObservation | None,
    prediction: SunEstimate | None,
    ephemeris: SunEstimate | None,
    config: PolicyConfig = PolicyConfig(),
    now: float | None = None,
) -> SunEstimate | None:
    """The policy as a pure function (see module docstring).

    ``prediction`` is the filter's estimate at ``t`` (already including any accepted
    observation); ``fresh_observation`` is the last accepted one, or None.  ``now`` is
    the present when ``t`` lies ahead (a setpoint aimed at mid-period): an observation's
    freshness is judged against the present, not against the aim time.
    """
    if prediction is not None and prediction.sigma_deg > config.max_predicted_sigma_deg:
        prediction = None
    fresh = (
        fresh_observation is not None
        and 0.0 <= (t if now is None else now) - fresh_observation.time <= config.max_obs_age_s
    )
    if prediction is not None:
        if fresh:
            return SunEstimate(
                t, prediction.az_deg, prediction.el_deg, prediction.covariance, EstimateSource.OBSERVED
            )
        if ephemeris is None:
            return SunEstimate(
                t, prediction.az_deg, prediction.el_deg, prediction.covariance, EstimateSource.PREDICTED
            )
        dominant = (
            EstimateSource.EPHEMERIS
            if ephemeris.sigma_deg < prediction.sigma_deg
            else EstimateSource.PREDICTED
        )
        return fuse([prediction, ephemeris], dominant, t)
    if fresh and fresh_observation is not None:
        o = fresh_observation
        s2 = o.sigma_deg**2
        c = max(np.cos(np.radians(o.el_deg)), 1e-6)
        return SunEstimate(t, o.az_deg, o.el_deg, np.diag([s2 / (c * c), s2]), EstimateSource.OBSERVED)
    return ephemeris


#: Longest gap between, and age after, the two observations :func:`extrapolate_two` uses, s.
EXTRAPOLATE_MAX_S = 3600.0
#: ``tan(obliquity) (15 deg/h in rad)^2 / 2`` in deg/h^2: the largest departure rate of the
#: sun's small circle from a great circle (at the solstices).
CURVATURE_DEG_PER_H2 = float(np.tan(np.radians(23.44)) * np.radians(15.0) ** 2 / 2.0 * 180.0 / np.pi)


def extrapolate_two(o1: SunObservation, o2: SunObservation, t: float) -> SunEstimate | None:
    """The sun at ``t`` from two ENU observations, by rotation along their great circle.

    The sun moves at a constant rate on a small circle of geodesic curvature
    ``tan |dec|``; the great circle through two of its points departs from it by about
    ``tan |dec| w^2 tau (tau + dt) / 2`` (``w`` = 15 deg/h).  Without a site the
    declination is unknown, so its bound (23.44 deg) sets that term: 0.85 deg h^-2 times
    ``tau (tau + dt)``, 0.11 deg for 15 min ahead of frames 15 min apart.  The one-sigma
    per axis is ``s sqrt(1 + 2 (tau / dt)^2)`` (``s`` the larger observation sigma, ``dt``
    their separation, ``tau = t - t2``) plus that bound.  None when the observations are
    too close, too far apart or too old.
    """
    dt, tau = o2.time - o1.time, t - o2.time
    if not (60.0 <= dt <= EXTRAPOLATE_MAX_S and -dt <= tau <= EXTRAPOLATE_MAX_S):
        return None
    v1 = azel_to_enu(o1.az_deg, o1.el_deg)
    v2 = azel_to_enu(o2.az_deg, o2.el_deg)
    axis = np.cross(v1, v2)
    sin_a = float(np.linalg.norm(axis))
    if sin_a < 1e-9:
        return None
    axis /= sin_a
    rate = float(np.arctan2(sin_a, float(v1 @ v2))) / dt  # rad/s
    ang = rate * tau
    v = (
        v2 * np.cos(ang) + np.cross(axis, v2) * np.sin(ang) + axis * float(axis @ v2) * (1.0 - np.cos(ang))
    )  # Rodrigues
    az, el = enu_to_azel(v)
    tau_h, dt_h = abs(tau) / 3600.0, dt / 3600.0
    sig = max(o1.sigma_deg, o2.sigma_deg) * np.sqrt(
        1.0 + 2.0 * (tau / dt) ** 2
    ) + CURVATURE_DEG_PER_H2 * tau_h * (tau_h + dt_h)
    c = max(np.cos(np.radians(float(el))), 1e-6)
    return SunEstimate(
        float(t),
        float(az) % 360.0,
        float(el),
        np.diag([sig * sig / (c * c), sig * sig]),
        EstimateSource.PREDICTED,
    )


class SunPathSource(SunSource):
    """Sun source backed by the sun-path filter, with ephemeris fallback and persistence.

    Parameters
    ----------
    site : Site, optional
        Known site: seeds the filter, enables the ephemeris fallback, and stays the prior
        of every restart (a sky that puts the site more than ``site_mismatch_deg`` away is
        reported in :meth:`summary`, not followed).
    state_path : path, optional
        Learned state is loaded from here at start (if the file exists) and written by
        :meth:`save`.  A file that cannot be used (corrupt, or a state that is not physical
        or not plausible, :func:`~controller.sunpath.state.load_state`) never stops the
        start: one warning line is logged, the file is renamed aside as
        ``<name>.invalid-<UTC time>`` (never deleted) and the filter starts afresh (from
        the ephemeris at ``site`` when given; otherwise with no estimate until it has
        learned).  A file that cannot be read, or of another version, is left where it is
        and the learned state is not persisted this run.
    kalman_config, policy_config : optional tuning.
    store : Store, optional
        Persist in this SQLite store (entry ``sunpath``) instead of a file; a stored state
        that cannot be used is kept under ``sunpath.invalid-<UTC time>`` and the filter
        starts afresh, as for a file.
    now : float, optional
        The present, POSIX s, to judge the state file's time by (a state saved more than a
        day in the future is refused); default: the wall clock.  A caller on a simulated
        clock passes its own.
    """

    name = "sunpath"

    def __init__(
        self,
        site: Site | None = None,
        state_path: str | Path | None = None,
        kalman_config: KalmanConfig | None = None,
        policy_config: PolicyConfig | None = None,
        now: float | None = None,
        store: Store | None = None,
    ):
        self.site = site
        self.state_path = Path(state_path) if state_path is not None else None
        self.store = store
        self.policy = policy_config or PolicyConfig()
        self.persist = self.state_path is not None or store is not None
        self.state_note: str | None = None  # why the state file was not used, if it was not
        loaded = self._load(time.time() if now is None else float(now))
        self.kf: SunPathKalman = loaded if loaded is not None else SunPathKalman(kalman_config, site)
        self.ephemeris = EphemerisSource(site) if site is not None else None
        self.last_accepted: SunObservation | None = None

    def _load(self, now: float) -> SunPathKalman | None:
        """The learned state, or None after one warning line (see the class docstring)."""
        from .state import StateError, load_state

        if self.store is not None:
            return self._load_stored(now)
        if self.state_path is None:
            return None
        path = self.state_path
        try:
            kf = load_state(path, now=now)
            if kf is None:
                log.info(
                    f"{path}: no learned sun-path state yet; starting "
                    + ("from the ephemeris at the configured site" if self.site else "without one")
                )
            elif self.site is not None:
                self._check_site(path, kf)
                kf.site = kf.site or self.site  # the configured site is the prior from now on
            return kf
        except StateError as exc:
            start = (
                "starting from the ephemeris at the configured site"
                if self.site
                else "starting without a learned state"
            )
            if exc.reason in ("unreadable", "version"):
                self.persist = False  # not ours to move: another version, or permissions
                self.state_note = f"{exc}; {start}; the learned state will not be saved"
            else:
                stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
                aside = path.with_name(f"{path.name}.invalid-{stamp}")
                try:
                    path.rename(aside)
                    what = re.sub(r"; fix or remove (the file|it)$", "", str(exc))  # done: moved aside
                    self.state_note = f"{what}; kept it as {aside.name}; {start}"
                except OSError as err:
                    self.persist = False
                    self.state_note = (
                        f"{exc}; could not move it aside ({err.strerror}); "
                        f"{start}; the learned state will not be saved"
                    )
            log.warning(self.state_note)
            return None

    def use_store(self, store: Store, now: float) -> None:
        """Persist in ``store`` from now on; the state it holds (if any, and usable)
        replaces what was loaded from a file."""
        self.store, self.persist = store, True
        loaded = self._load_stored(now)
        if loaded is not None:
            self.kf = loaded

    def _load_stored(self, now: float) -> SunPathKalman | None:
        """:meth:`_load` from the store: a bad entry is copied aside, never lost."""
        from .state import STORE_KEY, StateError, load_from_store

        assert self.store is not None
        try:
            kf = load_from_store(self.store, now=now)
            if kf is not None and self.site is not None:
                self._check_site(Path(f"{self.store.path}: state {STORE_KEY!r}"), kf)
                kf.site = kf.site or self.site
            return kf
        except StateError as exc:
            start = "from the ephemeris at the configured site" if self.site else "without a learned state"
            if exc.reason == "version":
                self.persist = False
                self.state_note = f"{exc}; starting {start}; the learned state will not be saved"
            else:
                aside = f"{STORE_KEY}.invalid-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
                try:  # the row as stored: garbage or NaN cannot be parsed to be copied
                    self.store.copy_state(STORE_KEY, aside)
                    self.state_note = f"{exc}; kept it as {aside!r}; starting {start}"
                except Exception as err:  # noqa: BLE001 - a store that cannot even copy: do not touch it
                    self.persist = False
                    self.state_note = f"{exc}; could not keep a copy ({err}); starting {start}; not saving"
            log.warning(self.state_note)
            return None

    def _check_site(self, path: Path, kf: SunPathKalman) -> None:
        """Refuse a state learned at a site far from the configured one (StateError)."""
        from .state import StateError, learned_site

        assert self.site is not None
        site = learned_site(kf)
        if site is None:
            return
        lat, lon = site
        dlat, dlon = lat - self.site.latitude, float(wrap180(lon - self.site.longitude))
        if max(abs(dlat), abs(dlon)) > kf.config.site_mismatch_deg:
            raise StateError(
                f"{path}: invalid sun-path state: field 'filter.x[lat_deg, "
                f"lon_deg]': learned {dlat:+.3f}, {dlon:+.3f} deg from the "
                "configured site",
                "invalid",
            )

    def observe(self, obs: SunObservation) -> bool:
        """Give the filter one observation (ENU or sensor frame); True when accepted."""
        res = self.kf.update(obs)
        if res.accepted or res.reason == "waiting to initialise":  # buffered for the start
            self.last_accepted = obs  # never one the filter refused (NaN, past the zenith)
        return res.accepted

    def prediction(self, t: float) -> SunEstimate | None:
        """The filter's estimate at ``t`` as a PREDICTED SunEstimate.

        Before the filter has started (site unknown, fewer than a few hours of frames),
        the last two ENU observations are extrapolated along their great circle instead
        (:func:`extrapolate_two`), so sparse frames do not leave the trackers without a sun
        between frames; None when there are not two recent ones.
        """
        if not self.kf.initialised:
            enu = [o for o in self.kf.buffer if o.frame == "enu"]
            return extrapolate_two(enu[-2], enu[-1], t) if len(enu) >= 2 else None
        p = self.kf.predict(t)
        return SunEstimate(float(t), p.az_deg, p.el_deg, p.covariance, EstimateSource.PREDICTED)

    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        eph = self.ephemeris.estimate(t) if self.ephemeris is not None else None
        obs = self.last_accepted
        if obs is not None and not self.kf.initialised:
            # before the filter starts, a raw sensor azimuth is only usable in ENU
            obs = obs if obs.frame == "enu" else None
        return select_estimate(float(t), obs, self.prediction(t), eph, self.policy, now=now)

    def summary(self) -> dict:
        """What the filter has learned so far, and how it got there.

        Site (deg, north/east-positive) with one-sigma, sensor azimuth offset, counts of
        accepted and rejected observations (of the rejected: ``older`` than the state,
        ``invalid``), restarts from a self-consistent run (``reinitialised``) and re-bases
        after a clock step back (``rebased``).  With a site given: the learned site's
        offset from it and ``site_mismatch``, true when the learned site or a
        self-consistent sky lies more than ``site_mismatch_deg`` from it (then
        ``site_mismatch_lat_deg`` / ``site_mismatch_lon_deg`` give the sky's offset and
        ``site_mismatch_cause`` the likely mistake, :meth:`.SiteMismatch.likely_cause`): the
        loop should raise an alarm, as the site or the clock is wrong.  ``state_note``: why
        the state file was not used, when it was not.
        """
        kf = self.kf
        out: dict = {
            "mode": kf.mode,
            "site_given": self.site is not None,
            "initialised": kf.initialised,
            "accepted": kf.n_accepted,
            "rejected": kf.n_rejected,
            "older": kf.n_older,
            "invalid": kf.n_invalid,
            "reinitialised": kf.n_reinit,
            "rebased": kf.n_rebase,
        }
        if self.state_note is not None:
            out["state_note"] = self.state_note
        if kf.initialised:
            x = kf.x
            out.update(
                {
                    "lat_deg": float(x[LAT]),
                    "lon_deg": float(wrap180(x[LON])),
                    "lat_sigma_deg": kf.sigma(LAT),
                    "lon_sigma_deg": kf.sigma(LON),
                    "az_offset_deg": float(wrap180(x[AZOFF])),
                }
            )
        if self.site is not None:
            limit = kf.config.site_mismatch_deg
            far = False
            if kf.initialised:
                dlat = float(kf.x[LAT] - self.site.latitude)
                dlon = float(wrap180(kf.x[LON] - self.site.longitude))
                out.update({"site_offset_lat_deg": dlat, "site_offset_lon_deg": dlon})
                far = max(abs(dlat), abs(dlon)) > limit
            m = kf.site_mismatch
            out["site_mismatch"] = far or m is not None
            if m is not None:
                out.update(
                    {
                        "site_mismatch_lat_deg": m.lat_offset_deg,
                        "site_mismatch_lon_deg": m.lon_offset_deg,
                        "site_mismatch_cause": m.likely_cause(self.site, limit),
                    }
                )
        return out

    def save(self) -> None:
        """Persist the learned state atomically (no-op without ``state_path``).

        Never raises: a failure (disk full, a file put in the way) is one warning line, and
        the file on disk is left as it was.
        """
        from .state import StateError, save_state, save_to_store

        if not self.persist:
            return
        try:
            if self.store is not None:
                save_to_store(self.store, self.kf)
            elif self.state_path is not None:
                save_state(self.state_path, self.kf)
        except (StateError, StoreError, OSError, ValueError, sqlite3.Error) as exc:
            log.warning(
                f"{self.store.path if self.store else self.state_path}: sun-path state not saved: {exc}"
            )
