"""The sun-path Kalman filter as a JSON-ready dict, and back.

:mod:`.state` writes these dicts to disk atomically; this module decides what they hold.
A ``free`` state written before the orbit model (declination in deg and its rate in
deg/day instead of the orbit's ``(u, v)``) is converted on load.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import TYPE_CHECKING

import numpy as np

from ..sun.source import Site
from ..sun.types import SunObservation
from .kalman_config import DEC, FREE_MODEL, RATE, STATE_NAMES, STATE_NAMES_FREE, KalmanConfig
from .orbit import MEAN_MOTION_DEG_PER_DAY

if TYPE_CHECKING:
    from .kalman import SunPathKalman

#: ``kind`` of a Kalman snapshot.
KIND = "sunpath-kalman"


def kalman_to_dict(kf: SunPathKalman) -> dict:
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
        "n_accepted": kf.n_accepted,
        "n_rejected": kf.n_rejected,
    }


def kalman_from_dict(d: dict, cls: type[SunPathKalman]) -> SunPathKalman:
    """Inverse of :func:`kalman_to_dict`, building an instance of ``cls``.

    Raises
    ------
    ValueError, KeyError, TypeError
        The dict is not a Kalman snapshot, or is malformed (the caller names the file).
    """
    if d.get("kind") != KIND:
        raise ValueError("not a sun-path Kalman state")
    cfg = KalmanConfig(**d["config"])
    site = Site(**d["site"]) if d.get("site") else None
    kf = cls(cfg, site)
    kf.mode = d["mode"]
    x = np.asarray(d["x"], dtype=float)
    P = np.asarray(d["P"], dtype=float)
    if x.shape != (6,) or P.shape != (6, 6) or not (np.all(np.isfinite(x))
                                                     and np.all(np.isfinite(P))):
        raise ValueError("state vector must have 6 finite values and P 6x6")
    if kf.mode == "free" and d.get("free_model") != FREE_MODEL:
        x, P = free_state_from_dec_rate(x, P)  # state file from before the orbit model
    kf.ekf.x, kf.ekf.P = x, P
    kf.obliquity_applied = bool(d.get("obliquity_applied", False))
    kf.t = None if d["t"] is None else float(d["t"])
    kf.initialised = bool(d["initialised"])
    kf.buffer = [SunObservation(float(a), float(b), float(c), float(s))
                 for a, b, c, s in d.get("buffer", [])]
    kf.n_accepted = int(d.get("n_accepted", 0))
    kf.n_rejected = int(d.get("n_rejected", 0))
    return kf


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
