"""Choosing a day's samples balanced about solar noon: pairs mirrored about a centre.

The paper fits its parabola "over the interval before to after solar noon" (section 3-1)
and asks for "a proper distribution in morning and afternoon" (section 2-7).  Elevation is
not a parabola of time over a whole day, so a window that sits unevenly about noon pulls
the parabola's vertex towards its own centre, by an amount that changes with the season.
Keeping only samples whose mirror image about the noon is also a sample removes that pull
without knowing the truth: the centre is the point of the sampling grid, or the half-step
between two grid points, nearest the fitted noon, and the fit is iterated
(:func:`controller.sunpath.parabola.fit_mirrored`).

Times here are plain floats in one unit (the seed method uses hours since local midnight).
"""

from __future__ import annotations

import numpy as np

#: Default pairing tolerance as a fraction of the day's median sampling interval.
TOLERANCE_FRACTION = 0.1


def default_tolerance(T) -> float:
    """Pairing tolerance: :data:`TOLERANCE_FRACTION` of the median interval of ``T``.

    Frame times on a schedule jitter by seconds; a tenth of the interval (90 s at one frame
    per 15 min) accepts that jitter and never pairs a frame with its neighbour.  0 for
    fewer than two samples.
    """
    T = np.sort(np.asarray(T, dtype=float))
    dt = np.diff(T)
    dt = dt[dt > 0]
    return TOLERANCE_FRACTION * float(np.median(dt)) if dt.size else 0.0


def centre_candidates(T) -> np.ndarray:
    """Every midpoint ``(T_i + T_j) / 2`` with ``i <= j``, sorted and unique.

    On a regular schedule these are exactly the grid points and the half-steps between
    them that at least one mirrored pair supports, clouds or not.
    """
    T = np.asarray(T, dtype=float)
    i, j = np.triu_indices(T.size)
    return np.unique(0.5 * (T[i] + T[j]))


def nearest_centre(T, t: float) -> float:
    """The candidate centre (:func:`centre_candidates`) nearest ``t``; ties go earlier."""
    c = centre_candidates(T)
    if c.size == 0:
        raise ValueError("no samples")
    return float(c[int(np.argmin(np.abs(c - t)))])


def mirrored_mask(
    T, centre: float, tolerance: float | None = None, half_width: float | None = None
) -> np.ndarray:
    """Samples whose mirror image about ``centre`` is also a sample, paired one to one.

    Parameters
    ----------
    T : array_like
        Sample times (any order; same unit as the other arguments).
    centre : float
        Centre of symmetry, e.g. from :func:`nearest_centre`.
    tolerance : float, optional
        Largest ``|T_i + T_j - 2 centre|`` of a pair (default :func:`default_tolerance`).
        A sample within it of the centre is its own mirror and is kept.
    half_width : float, optional
        Keep only pairs with ``|T - centre| <= half_width + tolerance``.

    Returns
    -------
    ndarray of bool
        Mask over ``T``: True for the samples of the balanced set.
    """
    T = np.asarray(T, dtype=float)
    tol = default_tolerance(T) if tolerance is None else float(tolerance)
    keep = np.zeros(T.size, dtype=bool)
    d = T - centre
    used = np.zeros(T.size, dtype=bool)
    # From the centre outwards, so that a jittered sample pairs with its nearest mirror.
    for i in np.argsort(np.abs(d), kind="stable"):
        if used[i] or d[i] > tol:
            continue  # afternoon samples are found as partners
        if half_width is not None and abs(d[i]) > half_width + tol:
            break
        if abs(d[i]) <= tol:  # the sample at the centre mirrors itself
            used[i] = keep[i] = True
            continue
        gap = np.abs(d + d[i])
        gap[used] = np.inf
        gap[d <= tol] = np.inf  # a partner lies after the centre
        j = int(np.argmin(gap))
        if gap[j] <= tol:
            used[i] = used[j] = keep[i] = keep[j] = True
    return keep
