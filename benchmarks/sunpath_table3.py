"""Paper 000's Table 3 on the paper's own terms, over several noise draws and a sigma sweep.

The paper's 36 dates at Andimeshk with its sampling (every 15 min from 08:00 local, 35 a
day in February and 36 after), pvlib SPA truth, Gaussian noise of one-sigma ``sigma`` on
each tangent-plane axis (so the elevation noise is ``sigma``), and each day fitted on its
own (:func:`controller.sunpath.parabola.run_seed` defaults: the parabola of the samples
mirrored about the fitted noon).  Two skies on the same noise draws: cloud-free (the
paper's condition: its Table 4 base days all have their 35 or 36 observations) and with the
benchmark's cloud gaps (Poisson 0.7 a day, 15-90 min each).  Every figure is averaged over
``N_DRAWS`` noise draws and given with its spread.

Also here, on the same draws: the one-condition-at-a-time decomposition (fit window, prior
chained over days, clouds), the Kalman filter (site unknown) against the seed method, the
Santiago site, and Table 4 (noon predicted from the previous day plus n0 morning
observations) on cloud-free days.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from controller.sunpath.batch import run_kalman
from controller.sunpath.ephemeris import transit_time
from controller.sunpath.kalman import KalmanConfig
from controller.sunpath.parabola import run_seed

from .sunpath_common import (
    ANDIMESHK,
    N0_LIST,
    PAPER,
    PAPER_DATES,
    PAPER_RANGES,
    QUICK_DATES,
    SANTIAGO,
    Dataset,
    day_table,
    make_dataset,
    seed_predictions,
)

#: Noise sigmas of the sweep (deg, per tangent-plane axis).
SIGMAS_DEG = (0.0, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.42, 0.5)
#: The sigma the acceptance is quoted at: the benchmark's own (chosen before issue #15),
#: inside the issue's range.
CHOSEN_SIGMA_DEG = 0.3
#: The issue's range: the paper's camera through the paper's pipeline in this project's
#: render, RMS angular error 0.255 deg (clean globe) to 0.416 deg (1 mm bumps)
#: (benchmarks/results/hotspot.json, result.chain.seed.*.paper.rms_deg).
SIGMA_RANGE_DEG = (0.25, 0.42)
#: The issue's limit on the noon mean, s.
NOON_MEAN_LIMIT_S = 20.0
N_DRAWS, N_DRAWS_QUICK = 20, 3
N_KALMAN_DRAWS, N_KALMAN_DRAWS_QUICK = 5, 1
FIRST_SEED = 1000
SKIES = (("clear", 0.0), ("clouds", 0.7))
#: One condition at a time, from the paper's conditions to this benchmark's old ones.
DECOMPOSITION: tuple[tuple[str, dict, str], ...] = (
    ("seed", {}, ("each day's own parabola on samples mirrored about noon (the paper's Table 3 reading)")),
    ("whole_day", {"fit": "whole-day"}, "each day's own parabola on every sample"),
    (
        "mirrored_chained_prior",
        {"use_prior": True},
        "mirrored, yesterday's fit as prior, chained over consecutive days",
    ),
    (
        "whole_day_chained_prior",
        {"fit": "whole-day", "use_prior": True},
        "whole day, prior chained: this benchmark's 'seed' before issue #15",
    ),
)
SWEEP_VARIANTS = ("seed", "whole_day")
FIGURES = (
    "noon_mean_s",
    "noon_std_s",
    "declination_rmse_deg",
    "location_error_mean_deg",
    "days",
    "days_with_declination",
)


def draw(site, utc_offset_h: float, dates, sigma_deg: float, clouds_per_day: float, seed: int) -> Dataset:
    """One noise draw; the same ``seed`` gives the same noise with or without clouds.

    The observations carry ``sigma_deg`` as their one-sigma (floored at 0.001 deg), so the
    Kalman filter is told the noise it gets.
    """
    ds = make_dataset(
        site, utc_offset_h, dates=dates, noise_deg=sigma_deg, clouds_per_day=clouds_per_day, seed=seed
    )
    return replace(ds, sigma=np.full(ds.t.size, max(sigma_deg, 1e-3)))


def figures(site, rows) -> dict:
    """Table 3 figures of per-day rows against SPA: noon (s), declination, location (deg)."""
    t = day_table(site, rows)
    if not t.get("days"):
        return {k: None for k in FIGURES}
    return {
        "noon_mean_s": t["noon_error_s"]["mean"],
        "noon_std_s": t["noon_error_s"]["std"],
        "declination_rmse_deg": t["declination_error_deg"].get("rms"),
        "location_error_mean_deg": t["location_error_deg"].get("mean"),
        "days": t["days"],
        "days_with_declination": t["declination_error_deg"]["n"],
    }


def aggregate(per_draw: list[dict]) -> dict:
    """Mean, standard deviation, min and max over draws of each figure (finite values)."""
    out = {}
    for k in FIGURES:
        v = np.array([d[k] for d in per_draw if d.get(k) is not None], dtype=float)
        v = v[np.isfinite(v)]
        out[k] = (
            {
                "mean": float(v.mean()),
                "sd": float(v.std(ddof=1)) if v.size > 1 else 0.0,
                "min": float(v.min()),
                "max": float(v.max()),
                "draws": int(v.size),
            }
            if v.size
            else None
        )
    return out


def _seed(ds: Dataset, kw: dict) -> dict:
    m = ds.clear
    rows, _ = run_seed(ds.t[m], ds.az_obs[m], ds.el_obs[m], ds.utc_offset_h, lat_deg=ds.site.latitude, **kw)
    return figures(ds.site, rows)


def _kalman(ds: Dataset, mode: str) -> dict:
    rows, _ = run_kalman(ds.observations(), KalmanConfig(declination=mode), utc_offset_h=ds.utc_offset_h)
    return figures(ds.site, rows)


def noon_lines_hold(agg: dict) -> dict:
    """The issue's noon lines on one aggregate: std in the paper's range, |mean| <= 20 s."""
    lo, hi = PAPER_RANGES["noon_std_s"]
    std, mean = agg["noon_std_s"]["mean"], agg["noon_mean_s"]["mean"]
    return {
        "noon_std_in_paper_range": bool(lo <= std <= hi),
        "noon_mean_within_20_s": bool(abs(mean) <= NOON_MEAN_LIMIT_S),
    }


def _paper_lines(agg: dict, per_draw: list[dict]) -> dict:
    """The paper's figures next to the mean over draws, with ranges and draws inside."""
    lines = {
        "noon_std_s": ("noon_std_s", PAPER["noon_std_s"], PAPER_RANGES["noon_std_s"]),
        "noon_mean_s": ("noon_mean_s", PAPER["noon_mean_s"], (-NOON_MEAN_LIMIT_S, NOON_MEAN_LIMIT_S)),
        "declination_rmse_deg": (
            "declination_rmse_deg",
            PAPER["declination_rmse_deg"],
            PAPER_RANGES["declination_rmse_deg"],
        ),
        "location_error_mean_deg": ("location_error_mean_deg", 0.5, PAPER_RANGES["location_error_mean_deg"]),
    }
    out = {}
    for name, (k, paper, (lo, hi)) in lines.items():
        a = agg[k]
        inside = [lo <= d[k] <= hi for d in per_draw if d.get(k) is not None]
        out[name] = {
            "measured_mean_over_draws": a["mean"] if a else None,
            "sd_over_draws": a["sd"] if a else None,
            "paper": paper,
            "range": [lo, hi],
            "within": bool(a and lo <= a["mean"] <= hi),
            "draws_within": f"{sum(inside)}/{len(inside)}",
        }
    out["noon_mean_s"]["paper_two_standard_errors"] = list(PAPER_RANGES["noon_mean_s"])
    return out


def _table4(draws: list[Dataset]) -> dict:
    """Median |error| of the noon predicted from yesterday's own fit plus n0 morning
    observations, cloud-free, per fit window of the base day; mean over draws."""
    out = {}
    for fit in ("mirrored", "whole-day"):
        med: dict[str, list[float]] = {str(n0): [] for n0 in N0_LIST}
        for ds in draws:
            pred = seed_predictions(ds, fit=fit, gaps_too=False)["table4_noon_prediction"]
            for n0, values in med.items():
                values.append(pred[n0]["median_abs_error_s"])
        out[fit] = {
            n0: {
                "median_abs_error_s_mean": float(np.mean(v)),
                "sd_over_draws": float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
                "paper_median": PAPER["table4_median_abs_error_s"][n0],
                "paper_abs_range": PAPER["table4_abs_error_range_s"][n0],
            }
            for n0, v in med.items()
        }
    return out


def table3_block(quick: bool = False) -> dict:
    """The Table 3 block of ``heliotrack bench sunpath`` (see the module docstring)."""
    dates = QUICK_DATES if quick else PAPER_DATES
    n_draws = N_DRAWS_QUICK if quick else N_DRAWS
    n_kal = N_KALMAN_DRAWS_QUICK if quick else N_KALMAN_DRAWS
    seeds = [FIRST_SEED + k for k in range(n_draws)]
    sweep: dict[str, dict] = {}
    decomposition: dict[str, dict] = {}
    acceptance: dict[str, dict] = {}
    kalman: dict[str, dict] = {}
    holds_at: dict[str, list[float]] = {}
    table4: dict[str, dict] = {}
    for sky, clouds in SKIES:
        sweep[sky] = {}
        holds_at[sky] = []
        for sigma in SIGMAS_DEG:
            data = [draw(ANDIMESHK, 3.5, dates, sigma, clouds, s) for s in seeds]
            names = [n for n in DECOMPOSITION if sigma == CHOSEN_SIGMA_DEG or n[0] in SWEEP_VARIANTS]
            runs = {name: [_seed(ds, kw) for ds in data] for name, kw, _ in names}
            aggs = {name: aggregate(v) for name, v in runs.items()}
            cell = {name: aggs[name] | noon_lines_hold(aggs[name]) for name in SWEEP_VARIANTS}
            if sigma > 0:
                cell["seed"]["declination_rmse_over_sigma"] = (
                    aggs["seed"]["declination_rmse_deg"]["mean"] / sigma
                )
            sweep[sky][str(sigma)] = cell
            if all(noon_lines_hold(aggs["seed"]).values()):
                holds_at[sky].append(sigma)
            if sigma != CHOSEN_SIGMA_DEG:
                continue
            decomposition[sky] = {
                name: {"description": what, **aggs[name]} for name, _, what in DECOMPOSITION
            }
            acceptance[sky] = _paper_lines(aggs["seed"], runs["seed"])
            kal = {mode: [_kalman(ds, mode) for ds in data[:n_kal]] for mode in ("ephemeris", "free")}
            same_seed = runs["seed"][:n_kal]
            kalman[sky] = {
                "draws": n_kal,
                "seed": aggregate(same_seed),
                **{f"kalman_{m}": aggregate(v) for m, v in kal.items()},
                "kalman_default_noon_std_below_seed_every_draw": all(
                    k["noon_std_s"] < s["noon_std_s"] for k, s in zip(kal["ephemeris"], same_seed)
                ),
                "note": "site unknown to the filter; in ephemeris mode (the default) the "
                "declination is SPA's plus a learnt correction, not a measurement",
            }
            if sky == "clear":
                table4 = _table4(data)
    south = {}
    for sky, clouds in SKIES:
        data = [draw(SANTIAGO, -4.0, dates, CHOSEN_SIGMA_DEG, clouds, s) for s in seeds]
        south[sky] = {
            name: aggregate([_seed(ds, kw) for ds in data])
            for name, kw, _ in DECOMPOSITION
            if name in SWEEP_VARIANTS
        }
    bias = draw(ANDIMESHK, 3.5, dates, 0.0, 0.0, FIRST_SEED)
    m = bias.clear
    rows, _ = run_seed(bias.t[m], bias.az_obs[m], bias.el_obs[m], 3.5)
    noons = np.array([r.noon_utc for r in rows])
    noise_free = [
        {"date": r.date, "noon_error_s": float(e)}
        for r, e in zip(rows, noons - transit_time(noons, ANDIMESHK.longitude))
    ]
    summary = {
        "chosen_sigma_deg": CHOSEN_SIGMA_DEG,
        **{sky: {k: v["within"] for k, v in acceptance[sky].items()} for sky, _ in SKIES},
        **{f"sigmas_where_noon_holds_{sky}": holds_at[sky] for sky, _ in SKIES},
        **{
            f"kalman_ahead_{sky}": kalman[sky]["kalman_default_noon_std_below_seed_every_draw"]
            for sky, _ in SKIES
        },
    }
    return {
        "description": __doc__.split("\n\n")[0].replace("\n", " "),
        "site": ANDIMESHK.name,
        "dates": list(dates),
        "draws": n_draws,
        "seeds": seeds,
        "sampling": "every 15 min from 08:00 local: 35 a day in February, 36 after",
        "truth": "pvlib SPA transit (the paper's calendar noon agrees within 4 s but for two rows)",
        "noise": "Gaussian, one-sigma sigma_deg on each tangent-plane axis (elevation "
        "noise = sigma_deg; angular RMS = sigma_deg * sqrt(2))",
        "clouds_per_day": dict(SKIES),
        "chosen_sigma_deg": CHOSEN_SIGMA_DEG,
        "sigma_range_deg": list(SIGMA_RANGE_DEG),
        "sigma_range_source": "issue #15: the paper's camera through the paper's pipeline in "
        "this project's render (hotspot.json, chain.seed clean / 1 mm "
        "bumps, paper pipeline: RMS angular error 0.255 / 0.416 deg)",
        "summary": summary,
        "acceptance_at_chosen_sigma": acceptance,
        "sigma_sweep": sweep,
        "decomposition_at_chosen_sigma": decomposition,
        "kalman_vs_seed_same_draws": kalman,
        "santiago_at_chosen_sigma": south,
        "table4_clear_at_chosen_sigma": table4,
        "noise_free_per_day_seed": noise_free,
    }
