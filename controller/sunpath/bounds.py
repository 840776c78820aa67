"""What a physical, plausible sun-path state and observation look like.

One table serves the filter (an update that would leave these bounds is refused, and a
covariance is never allowed to widen past them) and the state file (a state outside them
is refused on load), so whatever the filter can save, it can load again.

Angles in degrees, times in POSIX seconds (UTC).  The state layout is in
:mod:`.kalman_config`.
"""

from __future__ import annotations

import math

import numpy as np

from ..sun.types import SunObservation
from .ephemeris import wrap180
from .kalman_config import AZOFF, DEC, LON, RATE, STATE_NAMES, STATE_NAMES_FREE

#: 2000-01-01T00:00:00Z: nothing this filter learned or saw can be older (RTC resets to
#: 1970 or 2000 are the usual way a wrong time gets in).
EPOCH_MIN_S = 946684800.0
#: A saved state may lie this far ahead of the caller's "now" (clock skew between the run
#: that saved and the one that loads), s.
FUTURE_SLACK_S = 86400.0
#: Largest one-sigma an observation may claim, deg (more says nothing about the sun).
MAX_OBS_SIGMA_DEG = 45.0


def state_limits(mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the state (after :func:`normalised`) in ``mode``.

    Latitude [-90, 90]; longitude [-180, 180]; azimuth offset [0, 360]; refraction scale
    [0, 3] (0: no atmosphere; 3 is far beyond any standard-atmosphere departure).
    ``free``: ``|u|, |v| <= 1`` (their vector's length is ``sin(obliquity)``, about 0.4).
    ``ephemeris``: the correction to SPA's declination within +-10 deg and its drift within
    +-1 deg/day (SPA is right to far better than either).
    """
    lo = np.array([-90.0, -180.0, -10.0, -1.0, 0.0, 0.0])
    hi = np.array([90.0, 180.0, 10.0, 1.0, 360.0, 3.0])
    if mode == "free":
        lo[DEC], hi[DEC] = -1.0, 1.0
    return lo, hi


def max_sigma(mode: str) -> np.ndarray:
    """Largest one-sigma of each state entry that still means something.

    Beyond these a variance is absurd (a latitude known to +-200 deg is not known at all);
    the filter clips its covariance to them (:func:`bound_covariance`) and a state file
    with a larger one is refused.
    """
    s = np.array([90.0, 180.0, 10.0, 1.0, 180.0, 3.0])
    if mode == "free":
        s[DEC] = s[RATE] = 1.0
    return s


def names(mode: str) -> tuple[str, ...]:
    """The state entries' names as the state file writes them."""
    return STATE_NAMES_FREE if mode == "free" else STATE_NAMES


def normalised(x: np.ndarray) -> np.ndarray:
    """The state with longitude wrapped to [-180, 180) and the azimuth offset to [0, 360)."""
    x = np.array(x, dtype=float)
    x[LON] = float(wrap180(x[LON]))
    x[AZOFF] = float(x[AZOFF] % 360.0)
    return x


def state_problem(x: np.ndarray, P: np.ndarray, mode: str) -> tuple[str, str] | None:
    """Why ``(x, P)`` is not a physical state of ``mode``: ``(field, reason)``, or None.

    ``field`` names the entry (``"x[lat_deg]"``, ``"P"``).  ``x`` is checked after
    :func:`normalised`; ``P`` must be finite, symmetric (to 1e-9 relative), positive
    semi-definite (to 1e-9 relative) and within :func:`max_sigma`.
    """
    x = np.asarray(x, dtype=float).ravel()
    P = np.asarray(P, dtype=float)
    nm = names(mode)
    if x.shape != (6,):
        return "x", f"has {x.size} entries, expected 6"
    if P.shape != (6, 6):
        return "P", f"has shape {P.shape}, expected (6, 6)"
    for i in range(6):
        if not math.isfinite(x[i]):
            return f"x[{nm[i]}]", f"{x[i]} is not finite"
    xn = normalised(x)
    lo, hi = state_limits(mode)
    for i in range(6):
        if not lo[i] <= xn[i] <= hi[i]:
            return f"x[{nm[i]}]", f"{x[i]:.6g} is outside [{lo[i]:g}, {hi[i]:g}]"
    if mode == "free" and math.hypot(x[DEC], x[RATE]) > 1.0:
        return f"x[{nm[DEC]}, {nm[RATE]}]", f"length {math.hypot(x[DEC], x[RATE]):.6g} > 1"
    if not np.all(np.isfinite(P)):
        return "P", "not finite"
    scale = max(float(np.max(np.abs(np.diag(P)))), 1e-300)
    if np.max(np.abs(P - P.T)) > 1e-9 * scale:
        return "P", "not symmetric"
    smax = max_sigma(mode)
    for i in range(6):
        if P[i, i] < 0.0:
            return f"P[{nm[i]}]", f"negative variance {P[i, i]:.6g}"
        if P[i, i] > smax[i] ** 2:
            return f"P[{nm[i]}]", f"one-sigma {math.sqrt(P[i, i]):.6g} is over {smax[i]:g}"
    if float(np.min(np.linalg.eigvalsh(0.5 * (P + P.T)))) < -1e-9 * scale:
        return "P", "not positive semi-definite"
    return None


def bound_covariance(P: np.ndarray, sigma_cap: np.ndarray) -> np.ndarray:
    """``P`` with no one-sigma above ``sigma_cap`` (row and column scaled: ``D P D``).

    The scaling keeps the correlations and positive semi-definiteness; entries already
    below their cap are untouched.
    """
    s = np.sqrt(np.clip(np.diag(P), 0.0, None))
    d = np.ones(6)
    over = s > sigma_cap
    d[over] = sigma_cap[over] / s[over]
    if not over.any():
        return P
    return P * np.outer(d, d)


def observation_problem(obs: SunObservation) -> str | None:
    """Why ``obs`` cannot be an observation of the sun, or None.

    Time, azimuth, elevation and sigma must be finite; the time at or after 2000-01-01;
    the elevation within [-90, 90] deg; the sigma in (0, 45] deg.
    """
    for name in ("time", "az_deg", "el_deg", "sigma_deg"):
        v = getattr(obs, name)
        try:
            finite = math.isfinite(float(v))
        except (TypeError, ValueError):
            finite = False
        if not finite:
            return f"{name} = {v!r} is not a finite number"
    if obs.time < EPOCH_MIN_S:
        return f"time {obs.time:.0f} is before 2000-01-01"
    if not -90.0 <= obs.el_deg <= 90.0:
        return f"el_deg = {obs.el_deg:.6g} is outside [-90, 90]"
    if not 0.0 < obs.sigma_deg <= MAX_OBS_SIGMA_DEG:
        return f"sigma_deg = {obs.sigma_deg:.6g} is outside (0, {MAX_OBS_SIGMA_DEG:g}]"
    return None


def time_problem(t: float, now: float | None) -> str | None:
    """Why POSIX ``t`` cannot be the time of a learned state, or None.

    Before 2000-01-01 is refused; so is more than :data:`FUTURE_SLACK_S` after ``now``,
    unless ``now`` is None or itself before 2000 (a clock that cannot judge).
    """
    if not math.isfinite(t):
        return f"{t} is not finite"
    if t < EPOCH_MIN_S:
        return f"{t:.0f} is before 2000-01-01"
    if now is not None and now >= EPOCH_MIN_S and t > now + FUTURE_SLACK_S:
        return (
            f"{t:.0f} is {(t - now) / 86400.0:.1f} days after the present "
            f"({now:.0f}); at most {FUTURE_SLACK_S / 86400.0:g} allowed"
        )
    return None
