"""Summary statistics of angular errors, as every benchmark reports them."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def error_stats(errs: Iterable[float | None]) -> dict:
    """Count, RMS, median, 95th percentile and maximum (deg, 4 decimals) of the finite
    errors in ``errs`` (deg); None and NaN (a frame with no error to give) are left out.
    ``{"n": 0}`` when none is left."""
    e = np.asarray([x for x in errs if x is not None and np.isfinite(x)], float)
    if e.size == 0:
        return {"n": 0}
    return {
        "n": int(e.size),
        "rms_deg": round(float(np.sqrt(np.mean(e**2))), 4),
        "median_deg": round(float(np.median(e)), 4),
        "p95_deg": round(float(np.percentile(e, 95)), 4),
        "max_deg": round(float(e.max()), 4),
    }
