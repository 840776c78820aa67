"""The sun placed by the sky's rings alone, for a camera whose sky is a product.

A clear sky's radiance is an indicatrix of the angle to the sun times a gradation by the
zenith angle (the CIE general skies, Perez).  Where the circumsolar aureole carries that
product out to the glare's rim, the gradation shifts the rim's isophote along the
vertical, and :func:`.skybg.sky_dipole`'s additive model of the sky at the rim falls short
(a third renderer's suns read 0.11 deg low).  In log light such a sky is a level per ring
around the sun plus a function of elevation, which the rings outside the rim measure
without extrapolating to it; the glare's own profile, read about an axis ``eps`` off the
sun's, adds ``-d ln P / d chi`` times ``eps`` (as in :func:`.skybg.sky_by_elevation`, there
in light).  Where the rim is the lens's glare, whose halo fills the inner rings without the
gradation, the same fit is 0.03-0.12 deg off; no frame tells the two apart
(docs/fisheye-rounds.md, a twenty-fourth round), so the choice is the camera's, learned
from the ephemeris when the bundle has the site (:class:`LocatorChoice`).  A cloud in the
rings leaves only the rim; where the rings are the choice, its fix is then moved by its
offset from theirs at that elevation, learned where both placed the sun
(:meth:`LocatorChoice.rim_as_rings`).

Conventions: ``eps`` along the tangent vectors (e1, e2) at the reading's axis (rad); ray
angle ``phi`` from e1 towards e2; directions are unit vectors in the camera frame.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .clearsky import ring_roughness
from .skybg import RING_EDGES
from .small import gradient, median

#: rounds of clipping the fit's outliers (3 MADs; it stops once they stop changing)
MAX_CLIP_ROUNDS = 8
#: the rings' fix is not used where it lies farther than this from the reading's axis, the
#: rim's fix of the pass before (deg): the product sky's correction of the rim is 0.2 deg at
#: most on the third renderer's clear days
MAX_SHIFT_DEG = 0.3
#: the rings are chosen once the sum or the median of their squared angles to the sun is
#: under this share of the rim's, over this many frames at least (:class:`LocatorChoice`)
LEAD, MIN_FRAMES = 0.5, 2
#: where the rings are the choice but place no sun, the rim's fix is moved by its median
#: offset from the rings' on the frames both placed, the sun within this many degrees of
#: elevation of it (at least :data:`MIN_OFFSETS` of them; :meth:`LocatorChoice.place`)
OFFSET_EL_DEG, MIN_OFFSETS = 2.0, 3
#: without the site, the choice by the sun's own path (:meth:`LocatorChoice.observe_path`):
#: a sight of both fixes kept at most every PATH_STEP_S, for PATH_KEEP_S (s; 720 at most),
#: the sun PATH_MIN_EL_DEG high at least; the paths are compared once PATH_MIN_SIGHTS span
#: PATH_MIN_SPAN_S (s), and again every PATH_EVERY sights
PATH_STEP_S, PATH_KEEP_S, PATH_MIN_EL_DEG = 120.0, 172800.0, 12.0
PATH_MIN_SIGHTS, PATH_MIN_SPAN_S, PATH_EVERY = 12, 3600.0, 5
#: nor where the rings are rougher than a clear sky's (:func:`.clearsky.ring_roughness`;
#: the third renderer's clear days read up to 0.30 with its CCD smear's column in them)
MAX_ROUGHNESS = 0.35


@dataclass(frozen=True)
class SkyReading:
    """The rings of a fit's last reading of the sky (:func:`.glare.fit_glare`).

    ``vals`` (n_rays, n_chi): samples in the sky model's units (grey, or light);
    ``chi`` (rad) their angles from ``axis``; ``phi`` the rays' angles about it; ``rho`` the
    rim's radius (rad); ``rays_ok``, ``sky``: the rays that count and the samples that look
    at the sky; ``e1``, ``e2`` the tangent basis at ``axis``; ``contrast``: the glare's peak
    less the sky, in the same units.
    """

    vals: np.ndarray
    chi: np.ndarray
    phi: np.ndarray
    rho: float
    rays_ok: np.ndarray
    sky: np.ndarray
    axis: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    contrast: float


def log_ring_offset(reading: SkyReading, x: np.ndarray) -> np.ndarray | None:
    """The sun's offset from the reading's axis that its rings' log light places it at (rad,
    along e1, e2).

    Model of each ray's mean of ``ln vals`` over each ring (:data:`.skybg.RING_EDGES`): a
    level per ring, ``-d ln P / d chi * (eps_1 cos phi + eps_2 sin phi)`` with ``P`` the
    rings' mean profile, and ``c1 x + c2 x^2 + c3 x^3 + c4 x (chi / rho - 1)``, ``x`` each
    sample's elevation less the axis's over ``rho`` (same shape as ``vals``).  Least squares,
    clipped at 3 MADs until the kept rows stop changing.  A ray's ring counts where all its
    samples are on the sky and positive; a ring needs 6 such rays, the fit 3 rings.  None
    when there is too little sky.
    """
    vals, chi, phi, rho = reading.vals, reading.chi, reading.phi, reading.rho
    good = reading.sky & reading.rays_ok[:, None] & np.isfinite(vals) & (vals > 0.0)
    if int(np.count_nonzero(good)) < 30:
        return None
    lv = np.log(np.where(good, vals, 1.0))
    n_col = good.sum(axis=0)
    if not (n_col > 0).all():
        return None
    dprof = gradient((lv * good).sum(axis=0) / n_col, chi)
    edges = np.searchsorted(chi, np.array(RING_EDGES) * rho)
    lo, hi = edges[:-1], edges[1:]
    wide = hi - lo >= 2
    if int(np.count_nonzero(wide)) < 3:
        return None
    lo, hi = lo[wide], hi[wide]
    at = np.stack([lo, hi], axis=1).ravel()
    n = (hi - lo).astype(float)

    def ring_sums(a: np.ndarray) -> np.ndarray:
        return np.add.reduceat(np.concatenate([a, a[..., :1] * 0], axis=-1), at, axis=-1)[..., ::2]

    ok = np.logical_and.reduceat(np.concatenate([good, good[:, :1]], axis=1), at, axis=1)[:, ::2]
    used = np.flatnonzero(ok.sum(axis=0) >= 6)
    if used.size < 3:
        return None
    ray, ring = np.nonzero(ok[:, used])
    k = used.size
    # design: a level per ring (one-hot), the glare's shift, the cubic in x and its term in
    # the ring's radius; solved by its normal equations (k + 6 unknowns, ~200 rows)
    A = np.zeros((ray.size, k + 6))
    A[np.arange(ray.size), ring] = 1.0
    y = (ring_sums(lv)[:, used] / n[used])[ray, ring]
    xx = (ring_sums(x)[:, used] / n[used])[ray, ring]
    d = (ring_sums(dprof) / n)[used][ring]
    A[:, k] = -d * np.cos(phi)[ray]
    A[:, k + 1] = -d * np.sin(phi)[ray]
    A[:, k + 2] = xx
    A[:, k + 3] = xx * xx
    A[:, k + 4] = A[:, k + 3] * xx
    A[:, k + 5] = xx * (ring_sums(chi) / n / rho - 1.0)[used][ring]
    n_par = k + 6
    if y.size < 2 * n_par:
        return None
    keep = np.ones(y.size, bool)
    sol = np.zeros(n_par)
    for _ in range(MAX_CLIP_ROUNDS):
        Ak = A[keep]
        try:
            sol = np.linalg.solve(Ak.T @ Ak, Ak.T @ y[keep])
        except np.linalg.LinAlgError:  # a ring's kept rays all but collinear
            return None
        res = np.abs(y - A @ sol)
        mad = 1.4826 * median(res[keep]) + 1e-9
        new = res <= 3.0 * mad
        if (new == keep).all() or int(np.count_nonzero(new)) < 2 * n_par:
            break
        keep = new
    return sol[k : k + 2]


def ring_direction(reading: SkyReading, up_cam: np.ndarray) -> np.ndarray | None:
    """The sun's direction placed by ``reading``'s rings (:func:`log_ring_offset`), or None
    when they are too few, too rough for a clear sky, or place it farther than
    :data:`MAX_SHIFT_DEG` from the reading's axis.  ``up_cam``: the zenith in the camera frame."""
    r = reading
    rough = ring_roughness(r.vals, r.chi, r.phi, r.rho, r.rays_ok, r.sky, r.contrast)
    if rough is None or rough > MAX_ROUGHNESS:
        return None
    up_a = min(max(float(r.axis @ up_cam), -1.0), 1.0)
    dirs_up = np.cos(r.phi) * float(r.e1 @ up_cam) + np.sin(r.phi) * float(r.e2 @ up_cam)
    sin_el = np.cos(r.chi)[None, :] * up_a + np.sin(r.chi)[None, :] * dirs_up[:, None]
    x = (np.arcsin(np.clip(sin_el, -1.0, 1.0)) - math.asin(up_a)) / r.rho
    eps = log_ring_offset(r, x)
    if eps is None or math.degrees(math.hypot(eps[0], eps[1])) > MAX_SHIFT_DEG:
        return None
    d = r.axis + eps[0] * r.e1 + eps[1] * r.e2
    return d / np.linalg.norm(d)


class LocatorChoice:
    """Which of the rim and the rings places this camera's sun better, learned from the
    ephemeris: each fix's squared angle to the sun over the last ``window`` frames where both
    were measured and within ``max_deg`` of it, compared by their sums and by their medians.
    A frame's fix is chosen from the frames before it, so the ephemeris never picks a
    frame's own answer.  The choice is the camera's (its sky's, its glare's): it is kept
    across sequences.  The rings lead when they lead by either measure: the sums see a rim
    that is good on most frames and far off on some (the second renderer's power-law look:
    0.0468 deg by the sums' choice, 0.0696 by the medians'); the medians see through a few
    frames under broken cloud where both fixes are 0.5-1 deg off, which had outweighed a
    clear sky's ordinary frames and handed a clear afternoon to the rim (the third
    renderer's clouds: the clear reference 0.125 deg by the sums' choice, 0.027 by the
    medians').  The rim has settled only when it leads by both.  Each frame where both
    placed the sun also keeps the rim's offset from the rings (:meth:`rim_as_rings`).
    """

    def __init__(
        self,
        window: int = 60,
        max_deg: float = 1.0,
        lead: float = LEAD,
        min_frames: int = MIN_FRAMES,
        settled: int = 20,
        every: int = 10,
        always: bool = False,
        prior: str | None = None,
    ):
        self._sq: deque[tuple[float, float]] = deque(maxlen=window)
        self._always = always  # the rings, wherever they place the sun (no choice learned)
        self._prior = prior == "rings"  # the calibration day's choice, until frames have chosen
        self._max, self._lead, self._min = max_deg, lead, min_frames
        self._settled, self._every, self._frames = settled, every, 0
        self._kept: tuple[tuple[float, float], tuple[float, float]] | None = None
        # the rim's fix less the rings', along the vertical and across it (rad), by elevation (deg)
        self._offsets: deque[tuple[float, float, float]] = deque(maxlen=4 * window)
        # without the site: sights of both fixes (t, rim ENU, rings ENU), and the squared RMS
        # of a site fitted to each (rim, rings) once they span enough of the sun's path
        self._path: deque[tuple[float, np.ndarray, np.ndarray]] = deque(maxlen=720)
        self._path_sq: tuple[float, float] | None = None
        self._path_new = 0

    @classmethod
    def of_camera(cls, gates: Any, orientation: Any) -> LocatorChoice | None:
        """The choice of a camera with ``gates`` (:class:`.gates.GateOptions`) and its bundle's
        ``orientation`` (its ``locator``, the calibration day's choice), or None when the
        gates leave the rim alone (``ring_locator`` off)."""
        if not gates.ring_locator:
            return None
        prior = None if orientation is None else orientation.locator
        return cls(always=gates.rings_always, prior=prior)

    def _measures(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The rim's and the rings' squared angles (deg^2): their sums, then their medians
        (kept until the next frame is counted: each frame asks twice)."""
        if self._kept is None:
            sq = np.array(self._sq)
            sums = (float(sq[:, 0].sum()), float(sq[:, 1].sum()))
            self._kept = sums, (float(np.median(sq[:, 0])), float(np.median(sq[:, 1])))
        return self._kept

    @property
    def rings(self) -> bool:
        """True when the rings' fixes have agreed with the sun better than the rim's, their
        sum or their median of squares under ``lead`` times the rim's, over ``min_frames``
        frames at least; before that, as the calibration day chose (``prior``); always True
        when so constructed (``always``)."""
        if self._always:
            return True
        if len(self._sq) < max(self._min, 1):
            return self._prior
        return any(rings < self._lead * rim for rim, rings in self._measures())

    @property
    def path_rings(self) -> bool:
        """Without the site: True when a site fitted to the rings' sights leaves under
        ``lead`` times the squared RMS of one fitted to the rim's (:meth:`observe_path`);
        before they are compared, as the calibration day chose (``prior``)."""
        if self._always:
            return True
        if self._path_sq is None:
            return self._prior
        rim, rings = self._path_sq
        return rings < self._lead * rim

    def observe_path(self, t: float, rim_enu: np.ndarray, rings_enu: np.ndarray) -> None:
        """Count one frame's two fixes (ENU) as sights of the sun at POSIX ``t``, without the
        site.  The sun's diurnal path is fixed by the site alone; an error of a locator that
        grows and shrinks with the sun's elevation (a sky model's) bends its sights off any
        such path, which no site fitted to them takes up.  So each locator's sights get their
        own site (:func:`.selfsite.fit_site`), and the residuals are compared as the squared
        angles to the ephemeris are with the site (third renderer, 20-min frames: the rim's
        site fitted to 0.09-0.11 deg, the rings' to 0.016-0.032, their errors 0.10-0.14 and
        0.014-0.032; the second renderer's look as described 0.010-0.021 and 0.065-0.075)."""
        from .selfsite import MIN_SHARE, fit_site

        if self._path and t - self._path[-1][0] < PATH_STEP_S:
            return
        if float(rim_enu[2]) < math.sin(math.radians(PATH_MIN_EL_DEG)):
            return  # under it the rim is cut by the horizon, its errors erratic (CIE sky 10)
        self._path.append((t, rim_enu, rings_enu))
        while t - self._path[0][0] > PATH_KEEP_S:
            self._path.popleft()
        self._path_new += 1
        ts = np.array([p[0] for p in self._path])
        if len(ts) < PATH_MIN_SIGHTS or ts[-1] - ts[0] < PATH_MIN_SPAN_S:
            return
        if self._path_sq is not None and self._path_new < PATH_EVERY:
            return
        self._path_new = 0
        sq = []
        for k in (1, 2):
            fit = fit_site(ts, np.array([p[k] for p in self._path]))
            ok = fit is not None and fit[0].n >= MIN_SHARE * len(ts)
            sq.append(fit[0].rms_deg ** 2 if ok and fit is not None else math.inf)
        if math.isfinite(min(sq)):
            self._path_sq = (sq[0], sq[1])

    @property
    def rim_settled(self) -> bool:
        """The rim has led on ``settled`` frames at least, by half the rings' squares in sum
        and in median: the rings are then read on one frame in ``every`` only (they cost
        0.3 ms a frame)."""
        if self._always or len(self._sq) < max(self._settled, 1):
            return False
        return all(rim < 0.5 * rings for rim, rings in self._measures())

    def observe(self, rim_deg: float, rings_deg: float) -> None:
        """Count one frame's two fixes by their angles to the sun (deg)."""
        if rim_deg <= self._max and rings_deg <= self._max:
            self._sq.append((rim_deg * rim_deg, rings_deg * rings_deg))
            self._kept = None

    def place(
        self,
        cand: Any,
        gates: list[Any],
        R: np.ndarray | None,
        up_cam: np.ndarray | None,
        lens: Any,
        t: float | None = None,
    ) -> Any:
        """``cand`` (a :class:`.default.Candidate`), placed by its rings when this camera's
        choice is the rings and their fix passes every gate of ``gates`` (:class:`.gates.Gate`;
        the ephemeris's among them); the frame counts towards the choice either way.  Where
        the rings are the choice but place no sun (a cloud in them) or not within the gates,
        the rim's fix less its offset from the rings' (:meth:`rim_as_rings`).  Without the
        ephemeris's gate (no site) the frame at POSIX ``t`` counts as sights of the sun's path
        instead (:meth:`observe_path`).  ``R``: ENU from camera; ``lens``
        (:class:`.lens.FisheyeLens`) puts the fix's centre in the image."""
        reading = cand.fit.sky_reading
        gate = next((g for g in gates if g.name == "ephemeris"), None)
        if cand.d_enu is None or R is None or up_cam is None or (gate is None and t is None):
            return cand
        # chosen from the frames before: never from this frame's fixes
        d, use = None, self.rings if gate is not None else self.path_rings
        if reading is not None:
            self._frames += 1
            if self.rim_settled and self._frames % self._every:
                return cand
            d = ring_direction(reading, up_cam)
        if d is not None:
            d_enu = R @ d
            if gate is not None:
                self.observe(gate.distance_deg(cand.d_enu), gate.distance_deg(d_enu))
            elif t is not None:
                self.observe_path(float(t), cand.d_enu, d_enu)
            v, h = _vertical_basis(d, up_cam)
            el = math.degrees(math.asin(min(max(float(d_enu[2]), -1.0), 1.0)))
            self._offsets.append((el, float((cand.d_cam - d) @ v), float((cand.d_cam - d) @ h)))
            if use and self._within(d, R, gates):
                return self._placed(cand, d, R, lens, "ring_locator")
        if use:
            moved = self.rim_as_rings(cand.d_cam, float(cand.el_deg), up_cam)
            if moved is not None and self._within(moved, R, gates):
                return self._placed(cand, moved, R, lens, "rim_by_rings")
        return cand

    def rim_as_rings(self, rim: np.ndarray, el_deg: float, up_cam: np.ndarray) -> np.ndarray | None:
        """The rim's fix ``rim`` (camera frame) less its median offset from the rings' fixes
        on the frames before where both placed the sun within :data:`OFFSET_EL_DEG` of
        ``el_deg`` (deg), or None with fewer than :data:`MIN_OFFSETS` of them.  Where the
        rings read the sun better, the rim's error is mostly its sky model's, which keeps its
        size and sign at an elevation: the third renderer's clouds with the site, 0.240 ->
        0.21 deg RMS, where 187 suns the rings did not place read 0.316 by the rim."""
        near = [(dv, dh) for el, dv, dh in self._offsets if abs(el - el_deg) <= OFFSET_EL_DEG]
        if len(near) < MIN_OFFSETS:
            return None
        dv, dh = np.median(np.array(near), axis=0)
        v, h = _vertical_basis(rim, up_cam)
        d = rim - dv * v - dh * h
        return d / np.linalg.norm(d)

    @staticmethod
    def _within(d: np.ndarray, R: np.ndarray, gates: list[Any]) -> bool:
        d_enu = R @ d
        return all(g.distance_deg(d_enu if g.frame == "enu" else d) <= g.radius_deg for g in gates)

    @staticmethod
    def _placed(cand: Any, d: np.ndarray, R: np.ndarray, lens: Any, flag: str) -> Any:
        """``cand`` placed at ``d`` (camera frame), flagged ``flag``; ``cand`` itself when ``d``
        is not in front of the lens."""
        uv, seen = lens.project(d[None, :])
        if not seen[0]:
            return cand
        d_enu = R @ d
        el = math.degrees(math.asin(min(max(float(d_enu[2]), -1.0), 1.0)))
        fit = replace(cand.fit, flags=[*cand.fit.flags, flag], centre_uv=(float(uv[0, 0]), float(uv[0, 1])))
        return replace(cand, fit=fit, d_cam=d, d_enu=d_enu, el_deg=el)


def _vertical_basis(d: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents at ``d``: towards the zenith ``up`` and across (both camera frame)."""
    v = up - float(up @ d) * d
    v = v / max(float(np.linalg.norm(v)), 1e-12)
    return v, np.cross(d, v)
