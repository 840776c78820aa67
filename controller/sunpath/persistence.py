"""The sun-path Kalman filter as a JSON-ready dict, and back.

:mod:`.state` writes these dicts to disk atomically; this module decides what they hold.
A ``free`` state written before the orbit model (declination in deg and its rate in
deg/day instead of the orbit's ``(u, v)``) is converted on load.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, fields
from typing import Any, Protocol, TypeVar

import numpy as np

from ..sun.source import Site
from ..sun.types import SunObservation
from .bounds import normalised, observation_problem, state_problem, time_problem
from .kalman_config import (
    DEC,
    DECLINATION_MODES,
    FREE_MODEL,
    RATE,
    STATE_NAMES,
    STATE_NAMES_FREE,
    KalmanConfig,
)
from .orbit import MEAN_MOTION_DEG_PER_DAY, ORBIT_RATES


class KalmanFilterLike(Protocol):
    """What a snapshot reads and writes of :class:`~controller.sunpath.kalman.SunPathKalman`.

    A protocol rather than an import, so that :mod:`.kalman` (which uses this module) and
    this module do not import each other.
    """

    mode: str
    config: KalmanConfig
    site: Site | None
    ekf: Any  # filterpy's ExtendedKalmanFilter (x, P)
    initialised: bool
    t: float | None
    obliquity_applied: bool
    buffer: list[SunObservation]
    n_accepted: int
    n_rejected: int


F = TypeVar("F", bound=KalmanFilterLike)

#: ``kind`` of a Kalman snapshot.
KIND = "sunpath-kalman"


def kalman_to_dict(kf: KalmanFilterLike) -> dict:
    """JSON-ready snapshot of ``kf`` (state, covariance, config, site, buffer, counters)."""
    return {
        "kind": KIND,
        "mode": kf.mode,
        "config": asdict(kf.config),
        "site": None if kf.site is None else asdict(kf.site),
        "initialised": kf.initialised,
        "t": kf.t,
        "state_names": list(STATE_NAMES_FREE if kf.mode == "free" else STATE_NAMES),
        "free_model": FREE_MODEL if kf.mode == "free" else None,
        "obliquity_applied": kf.obliquity_applied,
        # ravel: filterpy starts with a column vector until the filter initialises
        "x": [float(v) for v in np.asarray(kf.ekf.x, float).ravel()],
        "P": [[float(v) for v in row] for row in kf.ekf.P],
        "buffer": [[o.time, o.az_deg, o.el_deg, o.sigma_deg] for o in kf.buffer],
        **{name: getattr(kf, name) for name in COUNTERS},
    }


class SnapshotError(ValueError):
    """A snapshot field is malformed, not physical or not plausible.

    Attributes
    ----------
    field : str
        The field, as a path inside the snapshot (``"x[lat_deg]"``, ``"buffer[3]"``).
    why : str
        What is wrong with it, one line.
    """

    def __init__(self, field: str, why: str):
        self.field = field
        self.why = why
        super().__init__(f"field '{field}': {why}")


#: Counters of the snapshot (absent in older files: 0).
COUNTERS = ("n_accepted", "n_rejected", "n_older", "n_invalid", "n_reinit", "n_rebase")


def kalman_from_dict(d: dict, cls: Callable[[KalmanConfig, Site | None], F], now: float | None = None) -> F:
    """Inverse of :func:`kalman_to_dict`, building an instance of ``cls``; validated.

    Parameters
    ----------
    d : dict
        The snapshot.
    cls : callable
        ``cls(config, site)`` builds the filter:
        :class:`~controller.sunpath.kalman.SunPathKalman` (passed in to avoid a cycle).
    now : float, optional
        The present, POSIX s: a state or buffered observation more than a day after it is
        refused.  None: no such check (e.g. a state being replaced, not used).

    Raises
    ------
    SnapshotError
        A field is malformed, not physical (latitude outside [-90, 90] after the model's
        normalisation, non-finite values, a covariance that is not symmetric positive
        semi-definite or has absurd variances, :mod:`.bounds`) or not plausible (a time
        before 2000 or in the future of ``now``, negative counters, an unknown mode).
    """
    if not isinstance(d, dict) or d.get("kind") != KIND:
        raise SnapshotError("kind", f"expected {KIND!r}")
    mode = d.get("mode")
    if mode not in DECLINATION_MODES:
        raise SnapshotError("mode", f"{mode!r} is not one of {list(DECLINATION_MODES)}")
    cfg = _config(d.get("config"), mode)
    site = _site(d.get("site"))
    kf = cls(cfg, site)
    initialised = d.get("initialised")
    if not isinstance(initialised, bool):
        raise SnapshotError("initialised", f"{initialised!r} is not true or false")
    t = d.get("t")
    if t is None:
        if initialised:
            raise SnapshotError("t", "missing in an initialised state")
    else:
        if not _is_number(t):
            raise SnapshotError("t", f"{t!r} is not a number")
        why = time_problem(float(t), now)
        if why:
            raise SnapshotError("t", why)
    try:
        x = np.asarray(d["x"], dtype=float).ravel()
        P = np.asarray(d["P"], dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise SnapshotError("x" if "x" not in d else "P", f"not an array of numbers ({exc})") from None
    if x.shape != (6,) or P.shape != (6, 6):
        raise SnapshotError("x" if x.shape != (6,) else "P", "must be 6 values and 6x6")
    if mode == "free" and d.get("free_model") != FREE_MODEL and np.all(np.isfinite(x)):
        x, P = free_state_from_dec_rate(x, P)  # state file from before the orbit model
    if initialised:
        bad = state_problem(x, P, mode)
        if bad:
            raise SnapshotError(*bad)
        x = normalised(x)
    elif not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
        raise SnapshotError("x" if not np.all(np.isfinite(x)) else "P", "not finite")
    kf.ekf.x, kf.ekf.P = x, P
    kf.obliquity_applied = bool(d.get("obliquity_applied", False))
    kf.t = None if t is None else float(t)
    kf.initialised = initialised
    kf.buffer = _buffer(d.get("buffer", []), now)
    for name in COUNTERS:
        v = d.get(name, 0)
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise SnapshotError(name, f"{v!r} is not a count (an integer >= 0)")
        setattr(kf, name, v)
    return kf


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _config(c, mode: str) -> KalmanConfig:
    """The snapshot's tuning, checked: finite numbers, the right signs, known names."""
    if not isinstance(c, dict):
        raise SnapshotError("config", "missing or not a table")
    try:
        cfg = KalmanConfig(**c)
    except TypeError as exc:
        raise SnapshotError("config", str(exc)) from None
    if cfg.declination != mode:
        raise SnapshotError("config.declination", f"{cfg.declination!r} but mode is {mode!r}")
    if cfg.orbit_rate not in ORBIT_RATES:
        raise SnapshotError("config.orbit_rate", f"{cfg.orbit_rate!r} is not one of {list(ORBIT_RATES)}")
    at_least_one = ("iterations", "max_consecutive_rejects", "init_min_obs", "max_consecutive_older")
    for f in fields(cfg):
        v = getattr(cfg, f.name)
        if isinstance(v, str):
            continue
        if not _is_number(v) or not math.isfinite(v):
            raise SnapshotError(f"config.{f.name}", f"{v!r} is not a finite number")
        if v < 0 and f.name != "obliquity_sigma_deg":  # that one: <= 0 switches it off
            raise SnapshotError(f"config.{f.name}", f"{v!r} is negative")
        if f.name in at_least_one and (not isinstance(v, int) or v < 1):
            raise SnapshotError(f"config.{f.name}", f"{v!r} is not an integer >= 1")
    if cfg.gate_chi2 <= 0:
        raise SnapshotError("config.gate_chi2", f"{cfg.gate_chi2!r} is not > 0")
    return cfg


def _site(s) -> Site | None:
    if not s:
        return None
    if not isinstance(s, dict):
        raise SnapshotError("site", "not a table")
    try:
        site = Site(**s)
    except TypeError as exc:
        raise SnapshotError("site", str(exc)) from None
    for name, lim in (("latitude", 90.0), ("longitude", 180.0)):
        v = getattr(site, name)
        if not _is_number(v) or not -lim <= v <= lim:
            raise SnapshotError(f"site.{name}", f"{v!r} is outside [{-lim:g}, {lim:g}]")
    return site


def _buffer(rows, now: float | None) -> list[SunObservation]:
    """Observations buffered before the filter started, each checked like a new one."""
    if not isinstance(rows, list):
        raise SnapshotError("buffer", "not a list")
    out = []
    for i, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != 4 or not all(_is_number(v) for v in row):
            raise SnapshotError(f"buffer[{i}]", "not [time, az_deg, el_deg, sigma_deg]")
        t, az, el, sigma = (float(v) for v in row)
        o = SunObservation(t, az, el, sigma)
        why = observation_problem(o) or time_problem(o.time, now)
        if why:
            raise SnapshotError(f"buffer[{i}]", why)
        out.append(o)
    return out


def free_state_from_dec_rate(x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Convert an old ``free`` state (dec deg, rate deg/day) to the orbit's ``(u, v)``.

    ``u = sin(dec)`` and ``v = cos(dec) rate / n`` (``n`` the mean motion, so that the
    rotation of ``(u, v)`` reproduces the rate); the covariance goes through the Jacobian.
    """
    x = x.copy()
    d, r = np.radians(x[DEC]), np.radians(x[RATE])
    n = np.radians(MEAN_MOTION_DEG_PER_DAY)
    J = np.eye(6)
    J[DEC, DEC] = np.cos(d) * np.pi / 180.0
    J[RATE, DEC] = -np.sin(d) * r / n * np.pi / 180.0
    J[RATE, RATE] = np.cos(d) / n * np.pi / 180.0
    x[DEC], x[RATE] = np.sin(d), np.cos(d) * r / n
    return x, J @ P @ J.T
