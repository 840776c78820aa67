"""Scoring a scenario against the world's truth: pointing error and plane-of-array energy.

The world samples each tracker's true axis angles (from the emulated drive, never from
what the controller was told) and the true sun (pvlib SPA); :mod:`hil.truth` turns them
into panel normals with its own geometry.  The figures compare the panel with the sun and
with an ideal tracker of the same kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from controller.config import DualAxisTracker, SingleAxisTracker, TrackerConfig
from hil import truth
from hil.sky import SkySeries

#: What the summary's figures mean (written into summary.json).
DEFINITIONS = {
    "pointing_error_deg": "daylight truth samples (substeps per period) of cycles "
    "in TRACK mode, outside backtracking and rotation "
    "limits; dual-axis: angle "
    "between panel normal and the true sun; single-axis: "
    "angle between panel normal and the sun projected on "
    "the rotation plane",
    "energy_ratio": "beam irradiation on the plane of array (the sky's DNI) "
    "achieved / ideal tracker of the same kind (exact truth "
    "angles, with backtracking)",
    "poa_global_kwh_m2": "global plane-of-array irradiation, pvlib Perez "
    "transposition of the sky's GHI/DNI/DHI, albedo 0.2",
}


@dataclass(frozen=True)
class TruthGrid:
    """The world's truth at every sample time of a run."""

    t: np.ndarray  # POSIX s
    sun: truth.SunTruth  # pvlib SPA
    sun_vecs: np.ndarray  # ENU unit vectors towards the sun, one row per sample
    sky: SkySeries  # ghi, dni, dhi (W/m2), beam transmittance


@dataclass
class TruthTally:
    """What the world saw of one tracker: its panel normal at every daylight sample."""

    samples: list[int] = field(default_factory=list)  # indices into the sample grid
    normals: list[np.ndarray] = field(default_factory=list)
    pointing: list[float] = field(default_factory=list)  # counted samples only, deg


def panel(tr: TrackerConfig, angles: list[float], sun: np.ndarray) -> tuple[np.ndarray, float]:
    """The panel normal (ENU unit vector) from the drive's true angles (deg), and its
    pointing error (deg; NaN when the sample does not count: backtracking, or the sun
    outside the rotation limits)."""
    if isinstance(tr, DualAxisTracker):
        n = truth.dual_axis_normal(angles[0], angles[1])
        return n, float(truth.angle_deg(n, sun))
    assert isinstance(tr, SingleAxisTracker)
    n = truth.row_normal(angles[0], tr.axis_azimuth, tr.axis_tilt)
    _, true_rot, bt = truth.row_ideal_rotation(
        sun[None, :], tr.axis_azimuth, tr.axis_tilt, 180.0, tr.gcr, tr.cross_axis_tilt, tr.backtrack
    )
    if bt[0] or abs(true_rot[0]) > tr.max_angle:
        return n, math.nan
    return n, float(truth.row_pointing_error(angles[0], sun, tr.axis_azimuth, tr.axis_tilt))


def ideal_normals(tr: TrackerConfig, sun: np.ndarray) -> np.ndarray:
    """Normals of an ideal tracker of the same kind (exact angles, exact backtracking)."""
    if isinstance(tr, DualAxisTracker):
        return sun
    assert isinstance(tr, SingleAxisTracker)
    rot, _, _ = truth.row_ideal_rotation(
        sun, tr.axis_azimuth, tr.axis_tilt, tr.max_angle, tr.gcr, tr.cross_axis_tilt, tr.backtrack
    )
    return truth.row_normal(rot, tr.axis_azimuth, tr.axis_tilt)


def stats(values: list[float]) -> dict:
    """Mean, 95th percentile and maximum (rounded to 1e-5) and the count."""
    if not values:
        return {"mean": None, "p95": None, "max": None, "n": 0}
    a = np.asarray(values)
    return {
        "mean": round(float(a.mean()), 5),
        "p95": round(float(np.percentile(a, 95)), 5),
        "max": round(float(a.max()), 5),
        "n": int(a.size),
    }


def energy(tr: TrackerConfig, tally: TruthTally, grid: TruthGrid, hours_per_sample: float) -> dict:
    """Beam and Perez plane-of-array irradiation of a tracker and of its ideal twin.

    Returns ``energy_ratio`` (beam achieved / ideal), ``poa_global_kwh_m2`` and ``beam``
    (achieved, ideal) sums for plant totals.
    """
    if not tally.samples:
        return {"energy_ratio": None, "poa_global_kwh_m2": 0.0, "beam": (0.0, 0.0)}
    k = np.asarray(tally.samples)
    normals = np.asarray(tally.normals)
    sun = grid.sun_vecs[k]
    dni = grid.sky.dni[k]
    beam = float(np.sum(dni * np.clip(np.sum(normals * sun, axis=1), 0, None)))
    ideal = float(np.sum(dni * np.clip(np.sum(ideal_normals(tr, sun) * sun, axis=1), 0, None)))
    poa = truth.poa_global_perez(
        normals, grid.t[k], grid.sun.azimuth[k], grid.sun.elevation[k], grid.sky.ghi[k], dni, grid.sky.dhi[k]
    )
    return {
        "energy_ratio": round(beam / ideal, 6) if ideal > 0 else None,
        "poa_global_kwh_m2": round(float(np.sum(poa)) * hours_per_sample / 1000.0, 5),
        "beam": (beam, ideal),
    }
