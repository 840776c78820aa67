"""Day and window sky types: the paper's rule (``seed``) and the default rule.

Classes (paper 002): I clear, II partly cloudy, III overcast; stored as 1, 2, 3 (0: none).

``seed``     K_T >= K_T,I and D <= D_I -> I; K_T >= K_T,I and D_I < D <= D_II -> II;
             otherwise III.  D_I, D_II from the year's D (``range``: the one- and two-third
             points of [min D, max D]; ``tertiles``: the 1/3 and 2/3 quantiles) or fixed.
``default``  the pyranometric relative sunshine f (Erbs-inferred DNI >= 120 W/m2, see
             :mod:`controller.sky.sunshine`) with the WMO-style bands: I if f >= 0.8, III if
             f <= 0.2, else II.  Adding the paper's K_T gate or a D gate did not help on the
             benchmark (it reports both variants); see docs/skytype.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from controller.sun.source import Site

from .baselines import classify_by_fraction, classify_by_kt, detect_clearsky_fraction
from .clear_shift import clear_shift_rows
from .clearness import clearness_index_rows
from .fractal import variation_dimension_rows
from .grid import DayGrid, build_day_grid, to_posix_seconds
from .plausibility import (
    EDGE_GHI_W_M2,
    NIGHT_ELEVATION_DEG,
    NIGHT_GHI_W_M2,
    light_centre_rows,
    light_edge_rows,
)
from .settings import Method, SkyConfig, ThresholdRule
from .solar import cos_zenith_rows, daily_extraterrestrial_irradiation, row_geometry
from .sunshine import pyranometric_sunshine_fraction, sunshine_fraction

CLASS_NAMES = {0: "", 1: "I", 2: "II", 3: "III"}

#: Per-day columns of :attr:`DayResults.rows`; all but the first two are not in ``days``.
ROW_CHECK_COLUMNS = (
    "K_T",
    "H0_MJ",
    "valid_s",
    "ghi_max",
    "lit_night_s",
    "noon_offset_h",
    "edge_offset_h",
    "clear_shift_h",
    "clear_fit",
)


# --------------------------------------------------------------------------- rules


def seed_thresholds(
    d_values: np.ndarray, rule: ThresholdRule = "range", fixed: tuple[float, float] = (1.19, 1.37)
) -> tuple[float, float]:
    """(D_I, D_II) from a year's D values.

    ``range``: D_min + (D_max - D_min) / 3 and D_min + 2 (D_max - D_min) / 3 (the paper's
    "(max F - min F) / 3" read as a point of the spread of D); ``tertiles``: the 1/3 and 2/3
    quantiles; ``fixed`` (or fewer than three finite values): ``fixed``.
    """
    d = np.asarray(d_values, float)
    d = d[np.isfinite(d)]
    if rule == "fixed" or d.size < 3:
        return float(fixed[0]), float(fixed[1])
    if rule == "range":
        lo, hi = float(d.min()), float(d.max())
        return lo + (hi - lo) / 3.0, lo + 2.0 * (hi - lo) / 3.0
    if rule == "tertiles":
        q = np.quantile(d, [1 / 3, 2 / 3])
        return float(q[0]), float(q[1])
    raise ValueError(f"unknown threshold rule {rule!r}")


def classify_seed(d: np.ndarray, k_t: np.ndarray, d_i: float, d_ii: float, kt_i: float = 0.5) -> np.ndarray:
    """The paper's rule; 1/2/3 for I/II/III, 0 where D or K_T is NaN."""
    d, k = np.asarray(d, float), np.asarray(k_t, float)
    bright = k >= kt_i
    out = np.where(bright & (d <= d_i), 1, np.where(bright & (d <= d_ii), 2, 3))
    return np.where(np.isfinite(d) & np.isfinite(k), out, 0)


def classify_default(sun_fraction: np.ndarray, config: SkyConfig = SkyConfig()) -> np.ndarray:
    """The default rule (module docstring); 1/2/3, 0 where the sunshine estimate is NaN."""
    return classify_by_fraction(sun_fraction, *config.sunshine_bands)


# --------------------------------------------------------------------------- features


def _row_features(
    ghi: np.ndarray,
    dni: np.ndarray | None,
    t0: np.ndarray,
    step_s: int,
    site: Site,
    config: SkyConfig,
    h0_analytic: bool,
    with_clearsky: bool,
) -> dict[str, np.ndarray]:
    """All per-row features of a block of grid rows."""
    rows, n = ghi.shape
    geo = row_geometry(np.asarray(t0, float) + 0.5 * n * step_s)
    cz = cos_zenith_rows(t0, step_s, n, site.latitude, site.longitude, geo)
    has = np.isfinite(ghi)
    up = cz > 0
    missing_s = step_s * np.count_nonzero(up & ~has, axis=1)
    window = has & (cz > np.sin(np.radians(config.min_elevation_deg)))
    frac = variation_dimension_rows(
        np.where(has, ghi, 0.0).astype(np.float32),
        window,
        step_s,
        scales_s=config.scales_s,
        criterion=config.criterion,
        increments=config.increments,
    )
    h0 = (
        daily_extraterrestrial_irradiation(site.latitude, geo["declination"], geo["e0"])
        if h0_analytic
        else None
    )
    kt = clearness_index_rows(np.where(has, ghi, 0.0), has, cz, step_s, geo["e0"], h0)
    lit_night = has & (cz < np.sin(np.radians(NIGHT_ELEVATION_DEG))) & (ghi > NIGHT_GHI_W_M2)
    out = {
        "daylight_s": step_s * np.count_nonzero(up, axis=1).astype(float),
        "missing_daylight_s": missing_s.astype(float),
        "D": frac.D,
        "n_scales": frac.n_scales,
        "dt_max_s": frac.dt_max_s,
        "K_T": kt["K_T"],
        "H_MJ": kt["H"] / 1e6,
        "H0_MJ": kt["H0"] / 1e6,
        "sun_fraction_est": pyranometric_sunshine_fraction(
            np.where(has, ghi, 0.0), has, cz, step_s, geo["doy"]
        ),
        # for the plausibility checks (controller.sky.plausibility), not the classes
        "valid_s": step_s * np.count_nonzero(has, axis=1).astype(float),
        "ghi_max": np.max(np.where(has, ghi, -np.inf), axis=1, initial=-np.inf).astype(float),
        "lit_night_s": step_s * np.count_nonzero(lit_night, axis=1).astype(float),
        "noon_offset_h": light_centre_rows(ghi, has, t0, step_s, site.longitude, geo["eot_s"]),
        "edge_offset_h": light_edge_rows(has & (ghi > EDGE_GHI_W_M2), up, step_s),
    }
    if h0_analytic:  # whole days (a live window's few hours time no clock)
        out["clear_shift_h"], out["clear_fit"] = clear_shift_rows(
            ghi, has, t0, step_s, site.latitude, site.longitude, geo
        )
    if with_clearsky:
        month = pd.to_datetime(np.asarray(t0, float) + 43200, unit="s").month
        out["clear_fraction"] = detect_clearsky_fraction(
            np.where(has, ghi, 0.0),
            has,
            cz,
            step_s,
            geo["e0"],
            np.asarray(month),
            site.latitude,
            site.longitude,
            site.altitude,
        )
    if dni is not None:
        dv = np.isfinite(dni)
        out["sunshine"] = sunshine_fraction(np.where(dv, dni, 0.0), dv, cz)
        out["missing_dni_s"] = (step_s * np.count_nonzero(up & ~dv, axis=1)).astype(float)
    return out


@dataclass
class DayResults:
    """Per-day features and classes of a record.

    Attributes
    ----------
    days : pandas.DataFrame
        One row per kept day: ``date``, ``year``, ``month``, ``n_samples``, ``D``, ``K_T``,
        ``class`` (I/II/III, by ``config.method``), the class of every rule
        (``class_seed``, ``class_default``, ``class_kt`` and ``class_csd`` when computed),
        ``sun_fraction_est``, ``H_MJ``, ``H0_MJ`` (MJ/m2), the fit range (``n_scales``,
        ``dt_max_s``), and with DNI ``sunshine`` (relative sunshine) and ``truth``.
    excluded : pandas.DataFrame
        ``date``, ``n_samples``, ``reason`` of the days left out.
    thresholds : pandas.DataFrame
        Per year: ``year``, ``rule``, ``D_I``, ``D_II``, ``n_days``.
    step_s : int
        Grid spacing used, s.
    config : SkyConfig
    rows : pandas.DataFrame
        Every day of the grid, kept or not, with what the plausibility checks
        (:mod:`controller.sky.plausibility`) judge: ``date``, ``kept``, ``daylight_s``,
        ``valid_s`` (s of samples), ``ghi_max`` (W/m2), ``K_T``, ``H0_MJ``, ``lit_night_s``
        (s of GHI over 20 W/m2 with the sun computed more than 3 deg below the horizon) and
        ``noon_offset_h`` (the GHI-weighted circular mean time, h after solar noon),
        ``edge_offset_h`` (how far both edges of the lit period moved from the computed
        sunrise and sunset, h; see :func:`~controller.sky.plausibility.light_edge_rows`),
        ``clear_shift_h`` and ``clear_fit`` (a clear day's light against the computed sun,
        h later, and the fit's misfit; :func:`~controller.sky.clear_shift.clear_shift_rows`).
    """

    days: pd.DataFrame
    excluded: pd.DataFrame
    thresholds: pd.DataFrame
    step_s: int
    config: SkyConfig = field(default_factory=SkyConfig)
    rows: pd.DataFrame = field(default_factory=pd.DataFrame)


def analyse_grid(
    grid: DayGrid,
    site: Site,
    config: SkyConfig = SkyConfig(),
    *,
    with_clearsky: bool = False,
    progress: bool = False,
    chunk_days: int = 16,
) -> DayResults:
    """Features, thresholds and classes of every day of a :class:`DayGrid`.

    Parameters
    ----------
    grid : DayGrid
    site : Site
        Latitude, longitude (deg) and altitude (m) of the station.
    config : SkyConfig
    with_clearsky : bool
        Also compute the ``detect_clearsky`` baseline (slow: a few seconds per year).
    progress : bool
        Show a tqdm bar over blocks of days.
    chunk_days : int
        Days per vectorised block (bounds memory: 16 days of 1-s data is 1.4 M slots).
    """
    rows = grid.day_index.size
    parts: list[dict[str, np.ndarray]] = []
    starts = range(0, rows, chunk_days)
    if progress:
        from tqdm import tqdm

        starts = tqdm(starts, total=len(starts), unit="block", desc=f"classify ({rows} days)")
    for s in starts:
        e = min(rows, s + chunk_days)
        parts.append(
            _row_features(
                grid.ghi[s:e],
                None if grid.dni is None else grid.dni[s:e],
                grid.t0_posix[s:e],
                grid.step_s,
                site,
                config,
                True,
                with_clearsky,
            )
        )
    feats = {
        k: np.concatenate([p[k] for p in parts]) if parts else np.array([])
        for k in (parts[0] if parts else {"D": 0})
    }
    dates = pd.to_datetime(grid.dates)
    table = pd.DataFrame(
        {
            "date": dates.strftime("%Y-%m-%d"),
            "year": dates.year,
            "month": dates.month,
            "n_samples": grid.n_samples,
            **feats,
        }
    )
    reason = np.full(rows, "", dtype=object)
    if rows:
        reason[~np.isfinite(table["D"].to_numpy(dtype=float))] = (
            "no fractal dimension (too little daylight data)"
        )
        reason[table["daylight_s"].to_numpy() <= 0] = "no daylight (polar night)"
        reason[table["missing_daylight_s"].to_numpy() > config.max_missing_s] = (
            f"more than {config.max_missing_s:g} s of daylight missing"
        )
    keep = reason == ""
    rows_table = table.reindex(columns=["date", "daylight_s", *ROW_CHECK_COLUMNS]).assign(kept=keep)
    table = table.drop(columns=list(ROW_CHECK_COLUMNS[2:]), errors="ignore")
    excluded = pd.DataFrame(
        {
            "date": table["date"][~keep],
            "n_samples": table["n_samples"][~keep],
            "missing_daylight_s": table["missing_daylight_s"][~keep],
            "reason": reason[~keep],
        }
    ).reset_index(drop=True)
    days = table[keep].reset_index(drop=True)
    res = _classify_table(days, excluded, grid.step_s, config)
    res.rows = rows_table.reset_index(drop=True)
    return res


def _classify_table(days: pd.DataFrame, excluded: pd.DataFrame, step_s: int, config: SkyConfig) -> DayResults:
    thr_rows = []
    seed = np.zeros(len(days), dtype=int)
    for year, idx in days.groupby("year").groups.items():
        d_i, d_ii = seed_thresholds(days.loc[idx, "D"].to_numpy(), config.threshold_rule, config.d_thresholds)
        rule = config.threshold_rule if len(idx) >= 3 else "fixed"
        thr_rows.append({"year": int(year), "rule": rule, "D_I": d_i, "D_II": d_ii, "n_days": len(idx)})
        pos = days.index.get_indexer(idx)
        seed[pos] = classify_seed(
            days.loc[idx, "D"].to_numpy(), days.loc[idx, "K_T"].to_numpy(), d_i, d_ii, config.kt_threshold
        )
    default = classify_default(days["sun_fraction_est"].to_numpy(), config) if len(days) else np.zeros(0, int)
    names = np.vectorize(CLASS_NAMES.get, otypes=[object])
    days = days.copy()
    days["class_seed"] = names(seed) if len(days) else []
    days["class_default"] = names(default) if len(days) else []
    days["class_kt"] = names(classify_by_kt(days["K_T"].to_numpy(), *config.kt_bands)) if len(days) else []
    if "clear_fraction" in days:
        days["class_csd"] = names(
            classify_by_fraction(days["clear_fraction"].to_numpy(), *config.sunshine_bands)
        )
    days["class"] = days["class_default"] if config.method == "default" else days["class_seed"]
    if "sunshine" in days:
        truth = names(classify_by_fraction(days["sunshine"].to_numpy(), *config.sunshine_bands))
        truth[days["missing_dni_s"].to_numpy() > config.max_missing_s] = ""
        days["truth"] = truth
    thresholds = pd.DataFrame(thr_rows, columns=["year", "rule", "D_I", "D_II", "n_days"])
    return DayResults(days=days, excluded=excluded, thresholds=thresholds, step_s=step_s, config=config)


def classify_days(
    times,
    ghi,
    site: Site,
    *,
    dni=None,
    config: SkyConfig = SkyConfig(),
    step_s: int | None = None,
    with_clearsky: bool = False,
    progress: bool = False,
) -> DayResults:
    """Classify every day of a GHI record (the paper's use: a station's year).

    Parameters
    ----------
    times : array_like
        UTC sample times (POSIX s, datetime64 or tz-aware datetimes); any order, duplicates
        and gaps allowed.
    ghi : array_like
        Global horizontal irradiance, W/m2; NaN = missing.
    site : Site
    dni : array_like, optional
        Direct normal irradiance, W/m2: adds the sunshine-duration truth.
    config : SkyConfig
    step_s : int, optional
        Grid spacing, s (1..60, a divisor of a day); inferred from the data if omitted.
    with_clearsky : bool
        Also compute the ``detect_clearsky`` baseline.
    progress : bool
        tqdm progress bar.

    Returns
    -------
    DayResults
    """
    grid = build_day_grid(times, ghi, site.longitude, dni=dni, step_s=step_s)
    return analyse_grid(grid, site, config, with_clearsky=with_clearsky, progress=progress)


# --------------------------------------------------------------------------- windows


@dataclass(frozen=True)
class WindowClass:
    """Sky type of a recent window of pyranometer samples (the controller's rolling input).

    Attributes
    ----------
    sky_class : int
        1 (I clear), 2 (II partly cloudy), 3 (III overcast), 0 (not enough daylight data).
    D : float
        Fractal dimension of the window's daylit part (NaN if < 3 scales fit).
    K_T : float
        Window clearness: ground over extraterrestrial horizontal irradiation, daylit part.
    sun_fraction : float
        Pyranometric relative sunshine of the daylit part.
    daylight_s, missing_s : float
        Daylit duration of the window and how much of it had no sample, s.
    n_samples : int
        Samples with a finite GHI in the window.
    method : str
        Rule used.
    """

    sky_class: int
    D: float
    K_T: float
    sun_fraction: float
    daylight_s: float
    missing_s: float
    n_samples: int
    method: str

    @property
    def name(self) -> str:
        """'I', 'II', 'III' or ''."""
        return CLASS_NAMES[self.sky_class]


def classify_window(
    times,
    ghi,
    site: Site,
    *,
    hours: float | None = None,
    end=None,
    method: Method | None = None,
    config: SkyConfig = SkyConfig(),
    step_s: int | None = None,
    min_daylight_s: float = 1800.0,
) -> WindowClass:
    """Classify the last ``hours`` of (time, GHI) samples at a site.

    Parameters
    ----------
    times : array_like
        UTC sample times (POSIX s, datetime64 or tz-aware datetimes), any order.
    ghi : array_like
        GHI, W/m2 (NaN = missing).
    site : Site
    hours : float, optional
        Window length; samples older than ``end - hours`` are ignored.  All samples if None.
    end : float or datetime, optional
        End of the window (POSIX s or UTC datetime); default the latest sample.
    method : {"default", "seed"}, optional
        Overrides ``config.method``.  ``seed`` uses the fixed ``config.d_thresholds``
        (a window has no year of D to take tertiles from).
    config : SkyConfig
    step_s : int, optional
        Grid spacing, s; inferred if omitted.
    min_daylight_s : float
        Less daylit data than this gives class 0; so do samples too sparse for the
        classifier's grid (median spacing over 90 s), whatever their span.

    Returns
    -------
    WindowClass
    """
    method = method or config.method
    t = to_posix_seconds(times)
    g = np.asarray(ghi, float)
    if t.size == 0:
        return WindowClass(0, np.nan, np.nan, np.nan, 0.0, 0.0, 0, method)
    t_end = float(t.max()) if end is None else float(to_posix_seconds(np.atleast_1d(end))[0])
    t_start = t_end - hours * 3600.0 if hours is not None else float(t.min())
    sel = (t >= t_start) & (t <= t_end)
    t, g = t[sel], g[sel]
    if t.size < 2:
        return WindowClass(0, np.nan, np.nan, np.nan, 0.0, 0.0, int(np.isfinite(g).sum()), method)
    if step_s is not None:
        step = int(step_s)
    else:
        try:
            step = _window_step(t)
        except ValueError:  # samples too sparse for a 1-min grid (a sensor read seldom): not judged
            return WindowClass(0, np.nan, np.nan, np.nan, 0.0, 0.0, int(np.isfinite(g).sum()), method)
    n = int(np.floor((t_end - t_start) / step)) + 1
    slot = np.clip(np.rint((t - t_start) / step).astype(np.int64), 0, n - 1)
    ok = np.isfinite(g)
    cnt = np.bincount(slot[ok], minlength=n)
    with np.errstate(invalid="ignore", divide="ignore"):
        row = (np.bincount(slot[ok], weights=g[ok], minlength=n) / cnt)[None, :]
    f = _row_features(row, None, np.array([t_start]), step, site, config, False, False)
    daylight, missing = float(f["daylight_s"][0]), float(f["missing_daylight_s"][0])
    d, kt, sf = float(f["D"][0]), float(f["K_T"][0]), float(f["sun_fraction_est"][0])
    if daylight - missing < min_daylight_s:
        cls = 0
    elif method == "seed":
        cls = int(classify_seed(np.array([d]), np.array([kt]), *config.d_thresholds, config.kt_threshold)[0])
    else:
        cls = int(classify_default(np.array([sf]), config)[0])
    return WindowClass(cls, d, kt, sf, daylight, missing, int(ok.sum()), method)


def _window_step(t: np.ndarray) -> int:
    from .grid import infer_step

    return infer_step(t)


__all__ = [
    "SkyConfig",
    "DayResults",
    "WindowClass",
    "classify_days",
    "classify_window",
    "analyse_grid",
    "seed_thresholds",
    "classify_seed",
    "classify_default",
    "CLASS_NAMES",
]
