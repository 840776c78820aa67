"""The site from the sun itself: a camera that knows where up and north are, but not where it is.

A bundle may give the camera's orientation and no ``[site]`` (the issue's bundle makes the
site optional).  The sun's direction in ENU at a known time then fixes the site, as a sun
sight with a known vertical and north fixes a ship's position: the sun's declination and
Greenwich hour angle depend on the time alone, and latitude and longitude are the two
unknowns of its azimuth and elevation.  So the estimator takes its own accepted detections
as sights; once ``MIN_SIGHTS`` of them, over at least ``MIN_SPAN_S``, agree on one
site (``MAX_RMS_DEG`` about the fit, ``MIN_SHARE`` of them within ``INLIER_DEG``), the
sun's ephemeris at that site gates the frames that follow, as the bundle's site would.  A fix that drifted onto a cloud's bright
edge is then more than a degree from where the sun must be, whatever came before it.

The fit is a robust least squares on (latitude, longitude) with SPA's geocentric sun
(:func:`controller.sunpath.ephemeris.geocentric_sun`) and refraction, started from a grid;
it is refitted every ``REFIT_EVERY`` sights once adopted.  Sights older than ``KEEP_S``
are dropped.  A site is the camera's: a night or an overcast day without a sight does not
change it, so it is kept through them.  But once its gate has refused sun-like glares for
``KEEP_S`` with no sight in between, it is forgotten and learned anew (a wrong one, or a
camera moved or its clock stepped, would otherwise refuse the sun, and so never be
corrected by new sights; a glint or a cloud's edge refused now and then is what the gate is
for, and leaves it as it was).  The refusals must run on: two more than ``REFUSAL_GAP_S``
apart (a night between them) start the count again.  Before, a glare refused at dusk had
the site forgotten at the next dawn, two hours after it with no sight between: the fourth
renderer's physical sun, refused near sunset, had the next day's first fix taken behind no
gate at all, 1.10 deg off.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ...sun.source import Site
from ...sunpath.ephemeris import azel_from_hour_angle, geocentric_sun

#: sights needed, over at least this many seconds, to adopt a site
MIN_SIGHTS, MIN_SPAN_S = 6, 600.0
#: they agree when this share of them lie within INLIER_DEG of the fit, at this RMS (deg)
MIN_SHARE, INLIER_DEG, MAX_RMS_DEG = 0.7, 0.5, 0.3
#: sights older than this (s) are dropped; an adopted site is refitted every REFIT_EVERY sights
KEEP_S, REFIT_EVERY = 7200.0, 20
#: refusals of the site's gate further apart than this (s) are not one run of them (a night)
REFUSAL_GAP_S = 10800.0


@dataclass(frozen=True)
class SiteFit:
    """A site fitted to sights: degrees; ``rms_deg`` of the sights it kept, ``n`` of them."""

    latitude: float
    longitude: float
    rms_deg: float
    n: int

    @property
    def site(self) -> Site:
        return Site(latitude=self.latitude, longitude=self.longitude, altitude=0.0)


def _directions(lat: np.ndarray, lon: np.ndarray, gha: np.ndarray, dec: np.ndarray) -> np.ndarray:
    """ENU unit vectors of the sun (..., 3) at sites (lat, lon) for geocentric (gha, dec)."""
    h = (gha + lon + 180.0) % 360.0 - 180.0
    az, el = azel_from_hour_angle(h, dec, lat)
    a, e = np.radians(az), np.radians(el)
    return np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)


def fit_site(
    times: np.ndarray,
    sights: np.ndarray,
    start: tuple[float, float] | None = None,
    inlier_deg: float = INLIER_DEG,
) -> tuple[SiteFit, np.ndarray] | None:
    """The site whose sun, at ``times`` (POSIX s), lies along ``sights`` (unit ENU vectors,
    (n, 3)); and each sight's angle from it (deg).  ``start``: (lat, lon) to refine from;
    without it a 2-deg grid is searched first.  None when the fit fails."""
    geo = geocentric_sun(times)
    gha = np.asarray(geo.sidereal_deg - geo.ra_deg, float)
    dec = np.asarray(geo.dec_deg, float)
    if start is None:  # a 2-deg grid on at most 8 of the sights, spread over them
        lat_g, lon_g = np.meshgrid(np.arange(-88.0, 89.0, 2.0), np.arange(-180.0, 180.0, 2.0), indexing="ij")
        sub = np.unique(np.linspace(0, len(times) - 1, min(len(times), 8)).round().astype(int))
        d = _directions(lat_g[..., None], lon_g[..., None], gha[sub], dec[sub])  # (nlat, nlon, n, 3)
        cost = np.minimum(np.einsum("...nk,nk->...n", d, sights[sub]), 1.0)
        k = np.unravel_index(int(np.argmax(np.sort(cost, axis=-1)[..., cost.shape[-1] // 2])), cost.shape[:2])
        start = (float(lat_g[k]), float(lon_g[k]))

    def angles(p: np.ndarray) -> np.ndarray:
        d = _directions(np.full(len(times), p[0]), np.full(len(times), p[1]), gha, dec)
        return np.degrees(np.arccos(np.clip(np.einsum("nk,nk->n", d, sights), -1.0, 1.0)))

    def solve(p0: np.ndarray, use: np.ndarray, loss: str) -> np.ndarray:
        def residual(p: np.ndarray) -> np.ndarray:
            d = _directions(np.full(int(use.sum()), p[0]), np.full(int(use.sum()), p[1]), gha[use], dec[use])
            return np.degrees(np.cross(d, sights[use])).ravel()

        bounds = ([-89.9, -540.0], [89.9, 540.0])
        return least_squares(residual, p0, loss=loss, f_scale=0.2, bounds=bounds).x

    try:  # robust first, then least squares on the sights within ``inlier_deg``
        p = solve(np.asarray(start, float), np.ones(len(times), bool), "soft_l1")
        keep = angles(p) <= inlier_deg
        if keep.sum() >= 3:
            p = solve(p, keep, "linear")
    except ValueError:
        return None
    lat, lon = float(p[0]), float((p[1] + 180.0) % 360.0 - 180.0)
    ang = angles(np.array([lat, lon]))
    keep = ang <= inlier_deg
    rms = float(np.sqrt(np.mean(ang[keep] ** 2))) if keep.any() else math.inf
    return SiteFit(lat, lon, rms, int(keep.sum())), ang


class SiteFromSun:
    """Sights of the sun (time, ENU direction) and the site they agree on, once they do."""

    def __init__(self) -> None:
        self.sights: deque[tuple[float, np.ndarray]] = deque(maxlen=64)
        self.fit: SiteFit | None = None
        self._since_fit = 0
        self._start: tuple[float, float] | None = None  # the last fit's site, adopted or not
        # its gate's run of refusals since the last sight: (the first, the latest), POSIX s
        self._refusals: tuple[float, float] | None = None

    def gate_refused(self, t: float | None, gates: list, dirs: list) -> None:
        """Note a frame at ``t`` whose sun-like glares (ENU unit vectors ``dirs``) the learned
        site's gate (``ephemeris_learned`` among ``gates``, :class:`.gates.Gate`) all refused."""
        for g in gates:
            if g.name == "ephemeris_learned" and t is not None:
                if all(d is not None and g.distance_deg(d) > g.radius_deg for d in dirs):
                    run = self._refusals
                    on = run is not None and abs(float(t) - run[1]) <= REFUSAL_GAP_S
                    self._refusals = (run[0] if on and run is not None else float(t), float(t))

    def stale(self, t: float | None) -> bool:
        """The site's gate has refused sun-like glares for ``KEEP_S`` before ``t``, with no
        sight within ``KEEP_S`` of it and no gap of ``REFUSAL_GAP_S`` in the refusals or after
        the latest: the site may no longer be the camera's (moved, or its clock stepped), and
        gating by it would shut the sun out.  Hours without a glare to refuse (a night, an
        overcast day) leave it as it was."""
        run = self._refusals
        if t is None or run is None or abs(t - run[1]) > REFUSAL_GAP_S or abs(t - run[0]) < KEEP_S:
            return False
        return not any(abs(t - s[0]) <= KEEP_S for s in self.sights)

    def add(self, t: float, d_enu: np.ndarray) -> SiteFit | None:
        """Record a sight; returns the site adopted (or still held), None until one is."""
        kept = [s for s in self.sights if abs(t - s[0]) <= KEEP_S]  # frames need not be in order
        self.sights = deque(kept + [(float(t), np.asarray(d_enu, float))], maxlen=self.sights.maxlen)
        self._since_fit, self._refusals = self._since_fit + 1, None
        ts = np.array([s[0] for s in self.sights])
        # a site held (from the day before, say) is refitted on sights that could adopt one
        short = len(ts) < MIN_SIGHTS or float(ts.max() - ts.min()) < MIN_SPAN_S
        if len(ts) < MIN_SIGHTS or (self.fit is not None and (self._since_fit < REFIT_EVERY or short)):
            return self.fit
        self._since_fit = 0
        ds = np.array([s[1] for s in self.sights])
        got = fit_site(ts, ds, self._start, INLIER_DEG)
        if got is None:
            self._start = None
            return self.fit
        fit, _ = got
        # the next fit starts here; a grid again if these sights did not agree
        self._start = (fit.latitude, fit.longitude) if fit.rms_deg <= MAX_RMS_DEG else None
        agree = (
            fit.n >= MIN_SIGHTS
            and fit.n >= MIN_SHARE * len(ts)
            and fit.rms_deg <= MAX_RMS_DEG
            and float(ts.max() - ts.min()) >= MIN_SPAN_S
        )
        self.fit = fit if agree else None
        return self.fit


#: the geocentric sun on a 10-min grid, shared by every learned site (it does not depend on one)
_GEO: dict[int, tuple[float, float]] = {}
GRID_S = 600.0


def _geo(k: int) -> tuple[float, float]:
    """(Greenwich hour angle, declination) of the sun at grid point ``k``, deg (cached)."""
    v = _GEO.get(k)
    if v is None:
        if len(_GEO) > 4096:
            _GEO.clear()
        g = geocentric_sun([k * GRID_S])
        v = (float(g.sidereal_deg[0] - g.ra_deg[0]), float(g.dec_deg[0]))
        _GEO[k] = v
    return v


class LearnedEphemeris:
    """The sun's ENU direction at a learned site: the geocentric sun interpolated on
    :data:`GRID_S` (error < 0.001 deg), then the site's hour angle and latitude."""

    def __init__(self, fit: SiteFit):
        self.fit = fit

    def direction(self, t: float) -> np.ndarray:
        k = math.floor(t / GRID_S)
        w = t / GRID_S - k
        (h0, d0), (h1, d1) = _geo(k), _geo(k + 1)
        gha = h0 + w * ((h1 - h0 + 180.0) % 360.0 - 180.0)
        dec = d0 + w * (d1 - d0)
        lat, lon = np.array([self.fit.latitude]), np.array([self.fit.longitude])
        return _directions(lat, lon, np.array([gha]), np.array([dec]))[0]
