"""Scoring of :mod:`benchmarks.fisheye_third`'s frames: counts, errors, elevation bands."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from .fisheye_suites import angle_deg, stats

FALSE_DEG = 1.0
BANDS = ((5.0, 17.0), (17.0, 25.0), (25.0, 40.0), (40.0, 90.0))


def sun_enu(az_deg, el_deg) -> np.ndarray:
    """Unit direction(s), shape (..., 3), in (East, North, Up) of azimuth ``az_deg`` (deg,
    clockwise from north) and elevation ``el_deg`` (deg, above the horizon)."""
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)


def score(records: Iterable[tuple[Any, float, float]]) -> dict:
    """Counts and errors of a look's frames.

    Parameters
    ----------
    records : iterable of (result, az_deg, el_deg)
        Each frame's :class:`~controller.vision.fisheye.FisheyeResult` (``found``,
        ``reason``, ``az_deg``, ``el_deg``, ``sigma_deg``) and the sun's true azimuth and
        elevation (deg).

    Returns
    -------
    dict
        ``n_frames``; ``found``: found within :data:`FALSE_DEG` of the sun (the error
        statistics are over these); ``false_detections``: found further off; ``not_found``:
        counts by reason; ``error``: RMS, median, p95, max (deg); ``elevation_bands``: per
        band of true elevation (:data:`BANDS`), count, RMS and mean signed elevation error
        (reported minus true, deg: negative reads the sun low); ``frac_within_2sigma``.
    """
    n, false = 0, 0
    not_found: dict[str, int] = {}
    rows = []  # (true el, error, signed el error, sigma)
    for res, az, el in records:
        n += 1
        if not res.found:
            why = str(res.reason)
            not_found[why] = not_found.get(why, 0) + 1
            continue
        r_az, r_el = float(res.az_deg), float(res.el_deg)
        err = angle_deg(sun_enu(r_az, r_el), sun_enu(az, el))
        if err > FALSE_DEG:
            false += 1
            continue
        rows.append((el, err, r_el - el, float(res.sigma_deg or math.nan)))
    a = np.array(rows) if rows else np.zeros((0, 4))
    bands = {}
    for lo, hi in BANDS:
        m = (a[:, 0] >= lo) & ((a[:, 0] < hi) | (hi == BANDS[-1][1]))
        bands[f"{lo:g}-{hi:g}"] = {
            "n": int(m.sum()),
            "rms_deg": round(float(np.sqrt(np.mean(a[m, 1] ** 2))), 4) if m.any() else None,
            "mean_signed_el_error_deg": round(float(a[m, 2].mean()), 4) if m.any() else None,
        }
    return {
        "n_frames": n,
        "found": len(rows),
        "not_found": dict(sorted(not_found.items())),
        "false_detections": false,
        "error": stats(a[:, 1]),
        "elevation_bands": bands,
        "frac_within_2sigma": round(float(np.mean(a[:, 1] < 2 * a[:, 3])), 3) if rows else None,
    }
