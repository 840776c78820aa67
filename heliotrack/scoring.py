"""Scoring a scenario against the world's truth: pointing error and plane-of-array energy.

The world samples each tracker's true axis angles (from the emulated drive, never from
what the controller was told) and the true sun (pvlib SPA, or a recording's
``truth.csv``); :mod:`hil.truth` turns them into panel normals with its own geometry.  The
figures compare the panel with the sun and with an ideal tracker of the same kind.

Memory stays flat however long the run: the truth is computed one day at a time
(:class:`WorldTruth`), and each tracker's figures are running sums (:class:`TruthTally`):
the panel normals of the current day only, the pointing errors as a count, sums and a
histogram at the summary's resolution (for the 95th percentile).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from controller.config import DualAxisTracker, SingleAxisTracker, TrackerConfig
from controller.sun.source import Site
from hil import truth
from hil.sky import SkySeries, sky_series

#: What the summary's figures mean (written into summary.json).
DEFINITIONS = {
    "pointing_error_deg": "daylight truth samples (substeps per period) of cycles "
    "in TRACK mode, outside backtracking and outside what "
    "the panel's travel can face (the drive's limits plus "
    "its mounting offset); dual-axis: angle "
    "between panel normal and the true sun; single-axis: "
    "angle between panel normal and the sun projected on "
    "the rotation plane; rms: root mean square; p95 to 1e-5 deg",
    "energy_ratio": "beam irradiation on the plane of array (the sky's DNI) "
    "achieved / ideal tracker of the same kind (exact truth "
    "angles, with backtracking)",
    "poa_global_kwh_m2": "global plane-of-array irradiation, pvlib Perez "
    "transposition of the sky's GHI/DNI/DHI, albedo 0.2",
}

#: Resolution of the pointing-error histogram (deg): the summary rounds to it.
RESOLUTION_DEG = 1e-5


@dataclass(frozen=True)
class TruthGrid:
    """The world's truth at every sample time of one stretch of a run (a day)."""

    t: np.ndarray  # POSIX s
    sun: truth.SunTruth  # pvlib SPA (or recorded)
    sun_vecs: np.ndarray  # ENU unit vectors towards the sun, one row per sample
    sky: SkySeries  # ghi, dni, dhi (W/m2), beam transmittance


class TruthSource(Protocol):
    """Where a run's truth comes from: the emulated world, or a recording."""

    def sun(self, t: np.ndarray) -> truth.SunTruth:
        """The true sun at POSIX times ``t``."""
        ...

    def sky(self, t: np.ndarray, day: int) -> SkySeries:
        """The sky at sorted POSIX times ``t``, all within day ``day`` of the run."""
        ...


class WorldTruth:
    """The emulated world's truth: pvlib SPA and the scenario's sky, one day at a time.

    Each day's clouds come from a random stream of its own (the scenario's seed for the
    first day, then the seed and the day's index), so a day's sky does not depend on how
    much of the run was computed before it.
    """

    def __init__(self, site: Site, skies: tuple[str, ...], linke_turbidity: float = 3.0, seed: int = 0):
        self.site = site
        self.skies = skies
        self.linke_turbidity = linke_turbidity
        self.seed = seed

    def sun(self, t: np.ndarray) -> truth.SunTruth:
        s = self.site
        return truth.sun_truth(t, s.latitude, s.longitude, s.altitude, s.temperature_c, self.linke_turbidity)

    def day_seed(self, day: int) -> int:
        if day == 0:
            return self.seed
        return int(np.random.SeedSequence([self.seed, day]).generate_state(1)[0])

    def sky_kind(self, day: int) -> str:
        return self.skies[day % len(self.skies)]

    def sky(self, t: np.ndarray, day: int) -> SkySeries:
        s = self.site
        return sky_series(
            t,
            s.latitude,
            s.longitude,
            s.altitude,
            {0: self.skies[day % len(self.skies)]},
            self.linke_turbidity,
            seed=self.day_seed(day),
        )


def truth_grid(source: TruthSource, t: np.ndarray, day: int) -> TruthGrid:
    """The truth at sample times ``t`` of day ``day``."""
    sun = source.sun(t)
    return TruthGrid(t, sun, sun.vectors, source.sky(t, day))


class Quantiles:
    """A histogram of non-negative values at a fixed resolution: exact quantiles to that
    resolution in memory bounded by the values' range, not by their number."""

    def __init__(self, resolution: float = RESOLUTION_DEG):
        self.resolution = resolution
        self.keys = np.zeros(0, np.int64)
        self.counts = np.zeros(0, np.int64)

    def add(self, values: np.ndarray) -> None:
        if values.size == 0:
            return
        q = np.round(np.asarray(values, float) / self.resolution).astype(np.int64)
        keys, inverse = np.unique(np.concatenate([self.keys, q]), return_inverse=True)
        weights = np.concatenate([self.counts, np.ones(q.size, np.int64)])
        self.keys, self.counts = keys, np.bincount(inverse, weights=weights).astype(np.int64)

    def merged(self, other: Quantiles) -> Quantiles:
        out = Quantiles(self.resolution)
        keys, inverse = np.unique(np.concatenate([self.keys, other.keys]), return_inverse=True)
        out.keys = keys
        out.counts = np.bincount(inverse, weights=np.concatenate([self.counts, other.counts])).astype(
            np.int64
        )
        return out

    def quantile(self, p: float) -> float:
        """Like ``numpy.percentile(values, 100 p)`` (linear between order statistics)."""
        n = int(self.counts.sum())
        if n == 0:
            return math.nan
        cum = np.cumsum(self.counts)
        rank = p * (n - 1)
        lo, hi = math.floor(rank), math.ceil(rank)
        v_lo = self.keys[np.searchsorted(cum, lo, side="right")] * self.resolution
        v_hi = self.keys[np.searchsorted(cum, hi, side="right")] * self.resolution
        return float(v_lo + (v_hi - v_lo) * (rank - lo))


@dataclass
class ErrorStats:
    """Running count, mean, RMS, maximum and 95th percentile of pointing errors (deg)."""

    n: int = 0
    total: float = 0.0
    squares: float = 0.0
    largest: float = 0.0
    hist: Quantiles = field(default_factory=Quantiles)

    def add(self, values: np.ndarray | list[float]) -> None:
        a = np.asarray(values, float)
        if a.size == 0:
            return
        self.n += int(a.size)
        self.total += float(a.sum())
        self.squares += float(np.sum(a * a))
        self.largest = max(self.largest, float(a.max()))
        self.hist.add(a)

    def merged(self, other: ErrorStats) -> ErrorStats:
        """The statistics of both sets of values together."""
        out = ErrorStats(self.n + other.n, self.total + other.total, self.squares + other.squares)
        out.largest = max(self.largest, other.largest)
        out.hist = self.hist.merged(other.hist)
        return out

    def summary(self) -> dict:
        """Mean, RMS, 95th percentile and maximum (rounded to 1e-5) and the count."""
        if self.n == 0:
            return {"mean": None, "rms": None, "p95": None, "max": None, "n": 0}
        return {
            "mean": round(self.total / self.n, 5),
            "rms": round(math.sqrt(self.squares / self.n), 5),
            "p95": round(self.hist.quantile(0.95), 5),
            "max": round(self.largest, 5),
            "n": self.n,
        }


def stats(values: list[float]) -> dict:
    """Mean, RMS, 95th percentile and maximum (rounded to 1e-5) and the count."""
    s = ErrorStats()
    s.add(values)
    return s.summary()


@dataclass
class TruthTally:
    """What the world saw of one tracker: running sums over the run, and the panel normals
    of the current stretch (until :meth:`flush` turns them into energy)."""

    pointing: ErrorStats = field(default_factory=ErrorStats)
    beam: float = 0.0  # sum of DNI x cos(incidence) over daylight samples, W/m2
    ideal: float = 0.0  # the same for an ideal tracker of the same kind
    poa_wh_m2: float = 0.0
    daylight_samples: int = 0
    samples: list[int] = field(default_factory=list)  # this stretch: indices into its grid
    normals: list[np.ndarray] = field(default_factory=list)

    def flush(self, tr: TrackerConfig, grid: TruthGrid, hours_per_sample: float) -> None:
        """Add the stretch's energy to the sums and forget its normals."""
        if not self.samples:
            return
        beam, ideal, poa = energy_sums(tr, np.asarray(self.samples), np.asarray(self.normals), grid)
        self.beam += beam
        self.ideal += ideal
        self.poa_wh_m2 += poa * hours_per_sample
        self.daylight_samples += len(self.samples)
        self.samples.clear()
        self.normals.clear()

    def energy(self) -> dict:
        """``energy_ratio`` (beam achieved / ideal) and ``poa_global_kwh_m2``."""
        return {
            "energy_ratio": round(self.beam / self.ideal, 6) if self.ideal > 0 else None,
            "poa_global_kwh_m2": round(self.poa_wh_m2 / 1000.0, 5),
        }


def panel(
    tr: TrackerConfig, angles: list[float], sun: np.ndarray, mount_offsets: list[float] | None = None
) -> tuple[np.ndarray, float]:
    """The panel normal and its pointing error.

    Parameters
    ----------
    tr : TrackerConfig
    angles : list of float
        Where the panel really points (deg): the drive's true output angles plus the
        mounting offsets (``DriveFirmware.panel_angles``).
    sun : numpy.ndarray
        ENU unit vector towards the true sun.
    mount_offsets : list of float, optional
        Per axis, how far the panel sits off its drive's output (deg, panel minus
        shaft; the world's ``[[hil.mount_offsets]]``); 0 when not given. They move the
        panel's travel: the drive's limits plus the offset.

    Returns
    -------
    normal : numpy.ndarray
        The panel normal (ENU unit vector).
    error : float
        Pointing error (deg); NaN when the sample does not count: a row backtracking, or
        a sun the panel's travel cannot face (a row 1.5 deg off its encoder, waiting at
        its -55 deg limit, cannot face a sun at -54).
    """
    off = list(mount_offsets) if mount_offsets is not None else [0.0] * len(angles)
    if isinstance(tr, DualAxisTracker):
        n = truth.dual_axis_normal(angles[0], angles[1])
        if not _dual_reaches(tr, off, sun):
            return n, math.nan
        return n, float(truth.angle_deg(n, sun))
    assert isinstance(tr, SingleAxisTracker)
    n = truth.row_normal(angles[0], tr.axis_azimuth, tr.axis_tilt)
    _, true_rot, bt = truth.row_ideal_rotation(
        sun[None, :], tr.axis_azimuth, tr.axis_tilt, 180.0, tr.gcr, tr.cross_axis_tilt, tr.backtrack
    )
    if bt[0] or not -tr.max_angle + off[0] <= true_rot[0] <= tr.max_angle + off[0]:
        return n, math.nan
    return n, float(truth.row_pointing_error(angles[0], sun, tr.axis_azimuth, tr.axis_tilt))


def _dual_reaches(tr: DualAxisTracker, off: list[float], sun: np.ndarray) -> bool:
    """Whether a dual-axis panel's travel (the limits plus the mounting offsets) holds the
    sun's azimuth (in some turn) and elevation."""
    el = math.degrees(math.asin(max(-1.0, min(1.0, float(sun[2])))))
    lo, hi = tr.elevation_limits
    if not lo + off[1] <= el <= hi + off[1]:
        return False
    az = math.degrees(math.atan2(float(sun[0]), float(sun[1])))
    lo, hi = tr.azimuth_limits[0] + off[0], tr.azimuth_limits[1] + off[0]
    return hi - lo >= 360.0 or (az - lo) % 360.0 <= hi - lo


def ideal_normals(tr: TrackerConfig, sun: np.ndarray) -> np.ndarray:
    """Normals of an ideal tracker of the same kind (exact angles, exact backtracking)."""
    if isinstance(tr, DualAxisTracker):
        return sun
    assert isinstance(tr, SingleAxisTracker)
    rot, _, _ = truth.row_ideal_rotation(
        sun, tr.axis_azimuth, tr.axis_tilt, tr.max_angle, tr.gcr, tr.cross_axis_tilt, tr.backtrack
    )
    return truth.row_normal(rot, tr.axis_azimuth, tr.axis_tilt)


def energy_sums(
    tr: TrackerConfig, k: np.ndarray, normals: np.ndarray, grid: TruthGrid
) -> tuple[float, float, float]:
    """Beam on the plane of array (achieved, ideal twin) and Perez global POA (W/m2
    summed over the samples ``k`` of ``grid``)."""
    sun = grid.sun_vecs[k]
    dni = grid.sky.dni[k]
    beam = float(np.sum(dni * np.clip(np.sum(normals * sun, axis=1), 0, None)))
    ideal = float(np.sum(dni * np.clip(np.sum(ideal_normals(tr, sun) * sun, axis=1), 0, None)))
    poa = truth.poa_global_perez(
        normals, grid.t[k], grid.sun.azimuth[k], grid.sun.elevation[k], grid.sky.ghi[k], dni, grid.sky.dhi[k]
    )
    return beam, ideal, float(np.sum(poa))
