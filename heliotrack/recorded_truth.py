"""What a recording's run is scored against: its ``truth.csv``, else the ephemeris.

``truth.csv`` columns: ``time_utc`` (ISO 8601 with a zone), ``sun_az_deg``,
``sun_el_deg``, ``sun_visible`` (0/1), and optionally ``ghi_w_m2``, ``dni_w_m2``,
``dhi_w_m2``, ``beam_transmittance`` (the sky the pyranometer and the energy tally see).
``hil record`` writes it; a survey of a real site can too.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from controller.errors import InputError
from controller.sun.source import Site
from controller.timestamps import parse_timestamp, to_iso
from hil import truth
from hil.sky import SkySeries

from .scoring import WorldTruth

TRUTH_FILE = "truth.csv"
TRUTH_COLUMNS = (
    "time_utc",
    "frame",
    "sun_az_deg",
    "sun_el_deg",
    "sun_visible",
    "ghi_w_m2",
    "dni_w_m2",
    "dhi_w_m2",
    "beam_transmittance",
)
SKY_COLUMNS = ("ghi_w_m2", "dni_w_m2", "dhi_w_m2", "beam_transmittance")
#: A frame named at a time rounded to the millisecond still belongs to its cycle.
TOLERANCE_S = 0.002
#: A frame older than this is not used (the controller predicts instead).
MAX_AGE_S = 120.0
#: A recorded sun further than this (deg) from the ephemeris is another site's or convention's.
TRUTH_GAP_DEG = 2.0


def write_truth(path: Path, rows: Iterable[dict]) -> int:
    """Write ``truth.csv`` rows (keys of :data:`TRUTH_COLUMNS`); return how many."""
    n = 0
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=TRUTH_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for row in rows:
            w.writerow(row)
            n += 1
    return n


def truth_row(t: float, frame: str, az: float, el: float, sky: dict[str, float]) -> dict:
    """One ``truth.csv`` row: the sun is visible when up and not behind a cloud."""
    tau = sky.get("beam_transmittance", 1.0)
    return {
        "time_utc": to_iso(t),
        "frame": frame,
        "sun_az_deg": f"{az:.6f}",
        "sun_el_deg": f"{el:.6f}",
        "sun_visible": int(el > 0 and tau >= 0.5),
        **{k: f"{sky[k]:.3f}" for k in SKY_COLUMNS if k in sky},
    }


class RecordedTruth:
    """The truth of a recording (``truth.csv``) where it covers, else the ephemeris.

    The recorded sun is interpolated as its offset from the ephemeris (so sparse rows
    still follow the sun's curved path); the recorded sky linearly.  A time farther than
    ``max_gap_s`` from both neighbouring rows is not covered.
    """

    def __init__(self, path: Path, fallback: WorldTruth):
        self.path = Path(path)
        self.fallback = fallback
        t, cols = self._read(self.path)
        if t.size == 0:
            raise InputError(f"{path}: no rows")
        order = np.argsort(t)
        self.t = t[order]
        self.cols = {k: v[order] for k, v in cols.items()}
        eph = fallback.sun(self.t)
        self.d_az = _wrap180(self.cols["sun_az_deg"] - eph.azimuth)
        self.d_el = self.cols["sun_el_deg"] - eph.elevation
        spacing = float(np.median(np.diff(self.t))) if self.t.size > 1 else 60.0
        self.max_gap_s = max(3 * spacing, MAX_AGE_S)
        self.has_sky = all(k in self.cols for k in SKY_COLUMNS)
        gap = float(np.max(np.hypot(self.d_az * np.cos(np.radians(eph.elevation)), self.d_el)))
        #: the largest angle (deg) between a recorded sun and the ephemeris's at the site
        self.worst_gap_deg = gap

    @staticmethod
    def _read(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        try:
            with open(path, newline="", encoding="utf-8-sig") as f:  # a spreadsheet's BOM too
                reader = csv.DictReader(f)
                fields = reader.fieldnames or []
                need = {"time_utc", "sun_az_deg", "sun_el_deg"}
                if not need <= set(fields):
                    raise InputError(
                        f"{path}: expected columns {', '.join(sorted(need))}, got {', '.join(fields)}"
                    )
                numeric = [c for c in ("sun_az_deg", "sun_el_deg", *SKY_COLUMNS) if c in fields]
                times: list[float] = []
                values: dict[str, list[float]] = {c: [] for c in numeric}
                for line, row in enumerate(reader, start=2):
                    times.append(
                        parse_timestamp(row["time_utc"], f"{path}:{line}: time_utc", require_zone=True)
                    )
                    for c in numeric:
                        try:
                            x = float(row[c])
                        except (TypeError, ValueError):
                            x = math.nan
                        if not math.isfinite(x):  # a NaN row was dropped from the score unseen
                            raise InputError(f"{path}:{line}: {c}: expected a finite number, got {row[c]!r}")
                        values[c].append(x)
        except UnicodeDecodeError as exc:
            raise InputError(f"{path}: not UTF-8 text ({exc.reason})") from None
        except OSError as exc:
            raise InputError(f"{path}: {exc.strerror or exc}") from None
        return np.asarray(times, float), {c: np.asarray(v, float) for c, v in values.items()}

    def covered(self, t: np.ndarray) -> np.ndarray:
        """Which of the times ``t`` the recording covers."""
        t = np.asarray(t, float)
        i = np.clip(np.searchsorted(self.t, t), 1, max(1, self.t.size - 1))
        before = self.t[np.maximum(i - 1, 0)]
        after = self.t[np.minimum(i, self.t.size - 1)]
        inside = (t >= self.t[0] - TOLERANCE_S) & (t <= self.t[-1] + TOLERANCE_S)
        near = np.minimum(np.abs(t - before), np.abs(after - t)) <= self.max_gap_s
        return inside & (near | (after - before <= self.max_gap_s))

    def sun(self, t: np.ndarray) -> truth.SunTruth:
        eph = self.fallback.sun(t)
        inside = self.covered(t)
        if not inside.any():
            return eph
        az = eph.azimuth + np.where(inside, np.interp(t, self.t, self.d_az), 0.0)
        el = eph.elevation + np.where(inside, np.interp(t, self.t, self.d_el), 0.0)
        return truth.SunTruth(np.asarray(t, float), np.mod(az, 360.0), el, eph.dni)

    def sky(self, t: np.ndarray, day: int) -> SkySeries:
        clear = self.fallback.sky(t, 0)
        if not self.has_sky:
            return clear
        inside = self.covered(t)
        rec = {k: np.interp(t, self.t, self.cols[k]) for k in SKY_COLUMNS}
        pick = {
            k: np.where(inside, rec[k], getattr(clear, k.split("_")[0]))
            for k in ("ghi_w_m2", "dni_w_m2", "dhi_w_m2")
        }
        tau = np.where(inside, rec["beam_transmittance"], clear.beam_transmittance)
        kinds = np.where(inside, "recorded", clear.kinds)
        return SkySeries(
            np.asarray(t, float), pick["ghi_w_m2"], pick["dni_w_m2"], pick["dhi_w_m2"], tau, kinds
        )

    def sky_kind(self, day: int) -> str:
        return "recorded"


class EphemerisTruth(WorldTruth):
    """No recording of the truth: pvlib SPA at the configured site, the clear-sky model."""

    def __init__(self, site: Site, linke_turbidity: float = 3.0):
        super().__init__(site, ("clear",), linke_turbidity)

    def sky_kind(self, day: int) -> str:
        return "unknown (scored on the ephemeris)"


def _wrap180(x: np.ndarray) -> np.ndarray:
    return (np.asarray(x) + 180.0) % 360.0 - 180.0
