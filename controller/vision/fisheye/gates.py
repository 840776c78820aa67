"""Where the sun can be: gates a candidate must pass before it is reported.

* **Sequence gate** (the paper's rule 3, judged in angle): within ``max_gap_s`` of the last
  accepted detection of the same sequence the sun is at most ``base_deg + rate_deg_per_min
  * minutes`` from it (the sun crosses the sky at <= 0.25 deg/min).  Only a detection whose
  rim held on ``anchor_min_inlier_fraction`` of its rays anchors it: a wrong weak one would
  otherwise shut the sun out of the frames that follow.  Nor does one that, ``release_after``
  times, alone refused a sun-like glare that moves like the sun: it is dropped (it was off
  the sun, reached by steps within the gate, e.g. onto a cloud's bright edge).  Without the
  site or a prior, once two anchors ``track_min_s`` apart give the sun's track
  (:func:`track_prediction`), the gate is centred where the track puts the sun and grows by
  ``track_rate_deg_per_min`` plus the anchors' error carried along, not the sun's whole rate.
  With no gate at all (a sequence's first sun, or the first after a gap, without the site or
  a prior) only a fix whose rim held on ``unvouched_min_inlier_fraction`` of its rays is
  reported: a weak one has nothing to vouch for it (``unvouched_glare``).  With the sequence
  gate alone, whose anchors are the camera's own fixes, ``sequence_min_inlier_fraction``.
  Behind either, a fix's sigma must also be at most ``self_vouched_max_sigma_deg``, 1 deg at
  3 sigma (:func:`max_self_vouched_sigma`): the sequence gate, 1.3-1.4 deg wide around a
  well-predicted sun, lets through a fix 1.1 deg off.
* **Prior gate**: a prediction handed in by the caller (in the loop: the sun-path filter's),
  ``max(min_deg, k_sigma * sigma + base_deg)`` around it.
* **Ephemeris gate**: with the site (bundle ``[site]``), the time and the orientation known,
  the sun is within ``ephemeris_deg`` of pvlib's position, less twice the orientation fit's
  residual over the root of its frames (the rotation's own error, to a first guess; bundle
  ``residual_deg`` and ``frames``).  A site learned from the sun (:mod:`.selfsite`) gates at
  ``ephemeris_deg`` less twice its fit's error over the root of its sights.  Either way a
  fix it lets through is still within ``ephemeris_deg`` of the true sun.  (Until
  2026-12-01 the bundle's gate was widened by five times the residual instead: a camera
  calibrated on the third renderer's clear day, residual 0.05 deg, let two fixes 1.01 and
  1.03 deg off through under its clouds.)
  The ephemeris is evaluated on a
  10-minute grid and interpolated (error < 0.001 deg), so the gate costs nothing per frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...sun.source import Site, solar_position
from ...sun.types import azel_to_enu
from .history import SUN_RATE_DEG_PER_MIN


@dataclass(frozen=True)
class GateOptions:
    base_deg: float = 1.0
    rate_deg_per_min: float = 0.3
    max_gap_s: float = 1800.0
    prior_min_deg: float = 1.0
    prior_k_sigma: float = 3.0
    ephemeris: bool = True
    ephemeris_deg: float = 1.0
    # the sequence gate anchors on a detection whose rim held on this share of its rays: a
    # weak one (a sun dimmed and cut by cloud, or a cloud's fleck taken for it) is reported
    # but does not shut the sun out of the next frames if it was wrong
    anchor_min_inlier_fraction: float = 0.7
    # the anchor is dropped after this many frames (not necessarily in a row: until the next
    # anchor) in which it alone refused a sun-like glare that moves like the sun
    release_after: int = 4
    # without the site or a prior: once two anchors at least ``track_min_s`` apart (and within
    # ``max_gap_s``) give the sun's track, the sequence gate is centred where the track puts
    # the sun now and grows by ``track_rate_deg_per_min``, not the sun's whole rate
    track_min_s: float = 120.0
    track_rate_deg_per_min: float = 0.05
    # the anchors' own error, carried along the track: ``track_anchor_deg`` times the time
    # since the last anchor over the baseline is added to the gate
    track_anchor_deg: float = 0.5
    # with no gate at all (no site, prior or anchor) a fix is reported only when its rim held
    # on this share of its rays: a weak one has nothing to vouch for it (the third
    # renderer's clouds without the site: dimmed suns found 2.5 and 4.3 deg off, 55-57 %)
    unvouched_min_inlier_fraction: float = 0.7
    # with the sequence gate alone a fix is reported only when its rim held on this share of
    # its rays: the gate follows the camera's own fixes, and a sun that a cloud dims and cuts
    # moves its rim's centre by steps within it (the third renderer's clouds without the
    # site: dimmed suns found 1.16-1.29 deg off on 41-48 %; our clouds' visible suns, 0.34
    # and 0.62 deg off on under half, and one 0.11 off)
    sequence_min_inlier_fraction: float = 0.5
    # and only while that gate is this narrow (deg): it widens with the time since its anchor
    # (0.3 deg a minute), and one 2-5 deg wide vouches for little (the third renderer's
    # clouds without the site, a fresh camera a sequence: dimmed suns found 1.5 and 1.75 deg
    # off on 56 and 62 % of their rays, 4 and 14 minutes after the last anchor); wider, a
    # rim must hold on ``unvouched_min_inlier_fraction``
    sequence_vouch_max_deg: float = 2.0
    # behind no gate but the camera's own (the sequence's, or none) a fix is reported only
    # when its sigma puts it within ``ephemeris_deg`` of the sun at 3 sigma: no gate holds it
    # there (the fourth renderer's clouds without the site: visible suns cut by a cloud's glow
    # found 1.07 and 1.10 deg off with sigmas 0.55 and 0.34, and 0.67-1.0 deg off with 0.37-0.47)
    self_vouched_max_sigma_deg: float = 1.0 / 3.0
    # without the site but with the orientation: learn the site from the detections and gate
    # by its ephemeris once they agree (:mod:`.selfsite`)
    learn_site: bool = True
    # and once it is learned, measure as with the bundle's site (:func:`.frames.sited`): the
    # learned gate refuses what those measures let through (the third renderer's clouds
    # without the site: 0 false detections either way, 0.239 -> 0.187 deg where visible; its
    # clear 1280 x 960 look 0.0300 -> 0.0263, a high sun's rings no longer read the smear)
    sited_once_learned: bool = True
    # place the sun by the sky's rings too: between the rim's fix and theirs as the frames
    # before weigh them against the ephemeris (with the site), or by theirs once they fit
    # the sun's own path better (without it); a camera whose sky is a product: :mod:`.rings`
    ring_locator: bool = True
    # place every sun the rings can, with no choice learned (the calibration's pass that fits
    # the rings' own rotation: :mod:`controller.calibration.fisheye_sun_calibration`)
    rings_always: bool = False


def min_rim_share(opts: GateOptions, gates: list[Gate]) -> float:
    """The least share of its rays that a fix's rim must hold on to be reported behind
    ``gates``: ``unvouched_min_inlier_fraction`` with no gate, ``sequence_min_inlier_fraction``
    with the sequence gate alone (its anchors are the camera's own fixes) while it is at most
    ``sequence_vouch_max_deg`` wide (wider, as with none), none with a gate that does not come
    from them (the site's ephemeris, a learned site's, the caller's prior)."""
    if any(g.name != "sequence" for g in gates):
        return 0.0
    if not gates or min(g.radius_deg for g in gates) > opts.sequence_vouch_max_deg:
        return opts.unvouched_min_inlier_fraction
    return opts.sequence_min_inlier_fraction


def max_self_vouched_sigma(opts: GateOptions, gates: list[Gate]) -> float:
    """The largest sigma (deg) of a fix reported behind ``gates``: ``self_vouched_max_sigma_deg``
    when none of them comes from outside the camera's own fixes (no gate, or the sequence's
    alone), else no bound (the site's ephemeris, a learned site's or the caller's prior holds
    the fix within its radius of the sun)."""
    if any(g.name != "sequence" for g in gates):
        return math.inf
    return opts.self_vouched_max_sigma_deg


def track_prediction(
    anchors: list[tuple[float, np.ndarray]], t: float, min_s: float
) -> tuple[np.ndarray, float] | None:
    """Where the sun is at ``t`` (POSIX s) on the track of the last anchor and the earliest
    one at least ``min_s`` before it (the longest baseline): the great circle through them,
    at their rate clamped to the sun's (:data:`SUN_RATE_DEG_PER_MIN`); and the baseline (s).
    None without such a pair, or when the pair moved unlike the sun (under half or over 1.5
    times its rate).

    ``anchors``: (time, unit direction) in time order, any one frame.  The sun follows a
    small circle (its declination's), which bends away from that great circle by
    ``tan(dec) <= 0.43`` per radian: with the anchors and ``t`` within half an hour (the
    gate's ``max_gap_s``), by at most about 0.2 deg.
    """
    if len(anchors) < 2:
        return None
    t1, d1 = anchors[-1]
    earlier = [(t0, d0) for t0, d0 in anchors[:-1] if t1 - t0 >= min_s]
    if not earlier:
        return None
    t0, d0 = earlier[0]
    ang = math.acos(float(np.clip(np.dot(d0, d1), -1.0, 1.0)))
    rate = math.degrees(ang) / ((t1 - t0) / 60.0)  # deg/min
    lo, hi = SUN_RATE_DEG_PER_MIN
    if not 0.5 * lo <= rate <= 1.5 * hi:
        return None
    axis = np.cross(d0, d1)
    axis /= np.linalg.norm(axis)
    step = math.radians(min(max(rate, lo), hi) * (t - t1) / 60.0)
    # Rodrigues: d1 turned by ``step`` about ``axis`` (axis is perpendicular to d1)
    out = d1 * math.cos(step) + np.cross(axis, d1) * math.sin(step)
    return np.asarray(out / np.linalg.norm(out)), t1 - t0


@dataclass(frozen=True)
class Gate:
    """A cone: unit ``centre`` (in ``frame``: ``"enu"`` or ``"camera"``) and ``radius_deg``."""

    name: str
    centre: np.ndarray
    radius_deg: float
    frame: str

    def distance_deg(self, d: np.ndarray) -> float:
        c = float(np.clip(np.dot(self.centre, d), -1.0, 1.0))
        return math.degrees(math.acos(c))


class Ephemeris:
    """pvlib SPA sun directions (ENU) at a site, on a cached grid, linearly interpolated.

    A missing grid point is computed with the rest of its block of ``block`` points in one
    SPA call: a call costs ~3 ms whatever its length (pandas and SPA's set-up), so frames
    minutes apart had paid it on most frames (a third of the default pipeline's time)."""

    def __init__(self, site: Site, grid_s: float = 600.0, block: int = 72):
        self.site = site
        self.grid_s = float(grid_s)
        self.block = int(block)
        self._cache: dict[int, np.ndarray] = {}

    def _at(self, k: int) -> np.ndarray:
        v = self._cache.get(k)
        if v is None:
            if len(self._cache) > 4096:
                self._cache.clear()
            first = k - k % self.block
            ks = np.arange(first, first + self.block)
            sp = solar_position(self.site, ks * self.grid_s)
            vecs = azel_to_enu(sp["azimuth"].to_numpy(float), sp["apparent_elevation"].to_numpy(float))
            self._cache.update(zip(ks.tolist(), vecs, strict=True))
            v = self._cache[k]
        return v

    def direction(self, t: float) -> np.ndarray:
        """Unit ENU vector of the sun at POSIX time ``t``."""
        k = math.floor(t / self.grid_s)
        w = t / self.grid_s - k
        v = (1.0 - w) * self._at(k) + w * self._at(k + 1)
        return v / np.linalg.norm(v)


@dataclass(frozen=True)
class CameraPrior:
    """An expected sun direction in the camera's own frame (OpenCV axes), for a camera
    that has no orientation but whose pose the caller knows: the panel-mounted loop's
    camera, from the drive's position and the row's learned offset.

    ``d_cam``: unit vector; ``sigma_deg``: its uncertainty (deg).
    """

    d_cam: np.ndarray
    sigma_deg: float


def prior_direction(prior) -> tuple[np.ndarray, float] | None:
    """(unit ENU vector, sigma deg) from an object with ``az_deg``, ``el_deg`` and
    ``sigma_deg`` (a SunObservation or SunEstimate) or a tuple (az, el, sigma)."""
    if prior is None:
        return None
    if isinstance(prior, (tuple, list)):
        az, el, sig = (float(x) for x in prior)
    else:
        az, el = float(prior.az_deg), float(prior.el_deg)
        sig = float(getattr(prior, "sigma_deg", 1.0))
    if not all(math.isfinite(x) for x in (az, el, sig)):
        return None
    return azel_to_enu(az, el), sig
