"""The paper's tables (per year) and figures, written for ``heliotrack classify``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from controller.sky.classify import DayResults
from controller.sky.grid import DayGrid

CLASSES = ("I", "II", "III")
#: Leading columns of days.csv, in this order; the rest follow.
DAY_COLUMNS = ("date", "n_samples", "D", "K_T", "class")


def threshold_table(res: DayResults) -> pd.DataFrame:
    """Table 1: D_I, D_II per year (and the rule that set them)."""
    return res.thresholds.round({"D_I": 4, "D_II": 4})


def frequency_table(res: DayResults, column: str = "class") -> pd.DataFrame:
    """Table 3: days and percent per class and year."""
    rows = []
    for year, g in res.days.groupby("year"):
        for c in CLASSES:
            n = int((g[column] == c).sum())
            rows.append(
                {"year": int(year), "class": c, "days": n, "percent": round(100.0 * n / max(len(g), 1), 2)}
            )
    return pd.DataFrame(rows, columns=["year", "class", "days", "percent"])


def class_stats_table(res: DayResults, column: str = "class") -> pd.DataFrame:
    """Table 4: mean and standard deviation (absolute and % of the mean) of D and K_T per class."""
    rows = []
    for year, g in res.days.groupby("year"):
        for c in CLASSES:
            s = g[g[column] == c]
            row = {"year": int(year), "class": c, "days": len(s)}
            for v in ("D", "K_T"):
                m, sd = (float(s[v].mean()), float(s[v].std(ddof=0))) if len(s) else (np.nan, np.nan)
                row.update(
                    {
                        f"mean_{v}": round(m, 4),
                        f"std_{v}": round(sd, 4),
                        f"std_{v}_pct": round(100 * sd / m, 2) if m else np.nan,
                    }
                )
            rows.append(row)
    return pd.DataFrame(rows)


def yearly_d_table(res: DayResults) -> pd.DataFrame:
    """Table 2: yearly mean D and its relative standard deviation."""
    g = res.days.groupby("year")["D"]
    out = pd.DataFrame(
        {
            "days": g.size(),
            "mean_D": g.mean().round(4),
            "std_D_pct": (100 * g.std(ddof=0) / g.mean()).round(2),
        }
    )
    return out.reset_index()


def monthly_d_table(res: DayResults) -> pd.DataFrame:
    """Fig. 2 data: monthly mean D per year."""
    g = res.days.groupby(["year", "month"])["D"]
    return pd.DataFrame(
        {"days": g.size(), "mean_D": g.mean().round(4), "std_D": g.std(ddof=0).round(4)}
    ).reset_index()


def agreement_table(res: DayResults) -> pd.DataFrame | None:
    """Share of days on which each rule matches the sunshine-duration truth (None without DNI)."""
    if "truth" not in res.days:
        return None
    d = res.days[res.days["truth"] != ""]
    rows = []
    for col, label in (
        ("class_default", "default (pyranometric sunshine)"),
        ("class_seed", "seed (paper: D and K_T)"),
        ("class_kt", "K_T alone"),
        ("class_csd", "detect_clearsky fraction"),
    ):
        if col in d:
            rows.append(
                {
                    "rule": label,
                    "days": len(d),
                    "agreement": round(float((d[col] == d["truth"]).mean()), 4) if len(d) else np.nan,
                }
            )
    return pd.DataFrame(rows)


def days_table(res: DayResults) -> pd.DataFrame:
    """days.csv: the required leading columns, ``truth`` next when present, then the rest."""
    d = res.days.copy()
    d["D"], d["K_T"] = d["D"].round(4), d["K_T"].round(4)
    lead = list(DAY_COLUMNS) + (["truth"] if "truth" in d else [])
    rest = [c for c in d.columns if c not in lead]
    return d[lead + rest].round(4)


def _markdown(df: pd.DataFrame) -> str:
    cols = [str(c) for c in df.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in df.itertuples(index=False):
        lines.append("| " + " | ".join("" if pd.isna(v) else str(v) for v in r) + " |")
    return "\n".join(lines) + "\n"


def write_tables(res: DayResults, out: Path) -> list[Path]:
    """Write every table as CSV and all of them, per year, in ``tables.md``."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    tables = {
        "thresholds": threshold_table(res),
        "yearly_D": yearly_d_table(res),
        "class_frequency": frequency_table(res),
        "class_stats": class_stats_table(res),
        "monthly_D": monthly_d_table(res),
    }
    agr = agreement_table(res)
    if agr is not None:
        tables["agreement"] = agr
    for name, t in tables.items():
        p = out / f"{name}.csv"
        t.to_csv(p, index=False)
        written.append(p)
    p = out / "days.csv"
    days_table(res).to_csv(p, index=False)
    written.append(p)
    if len(res.excluded):
        p = out / "excluded.csv"
        res.excluded.to_csv(p, index=False)
        written.append(p)
    # the tables this run has not, from an earlier run into the same folder, would be read
    # as this run's: gone (a reused --out had kept another station's agreement table)
    for name in ("excluded.csv", "agreement.csv"):
        if out / name not in written:
            (out / name).unlink(missing_ok=True)
    md = [
        f"# Day types ({res.config.method} rule in `class`)\n",
        f"Grid step {res.step_s} s; {len(res.days)} days kept, {len(res.excluded)} excluded.\n",
    ]
    for year in sorted(res.days["year"].unique()):
        md.append(f"\n## {year}\n")
        for name, t in tables.items():
            if "year" in t:
                md += [f"\n### {name}\n\n", _markdown(t[t["year"] == year].drop(columns="year"))]
    if agr is not None:
        md += ["\n## Agreement with the sunshine-duration truth (all years)\n\n", _markdown(agr)]
    p = out / "tables.md"
    p.write_text("".join(md))
    written.append(p)
    return written


def write_figures(res: DayResults, grid: DayGrid, out: Path) -> list[Path]:
    """Fig. 1 (one example day per class, GHI against solar time) and Fig. 2 (monthly mean D)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    written = []
    days = res.days
    dates = pd.to_datetime(grid.dates).strftime("%Y-%m-%d")
    row_of = {d: i for i, d in enumerate(dates)}
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=True)
    hours = np.arange(grid.n_slots) * grid.step_s / 3600.0
    for ax, c in zip(axes, CLASSES):
        s = days[days["class"] == c]
        ax.set_title(f"class {c}")
        ax.set_xlabel("local mean solar time (h)")
        if len(s) == 0:
            ax.text(0.5, 0.5, "no day", ha="center", transform=ax.transAxes)
            continue
        # the most typical day: D closest to the class median
        pick = s.iloc[int(np.argmin(np.abs(s["D"].to_numpy() - s["D"].median())))]
        ax.plot(hours, grid.ghi[row_of[pick["date"]]], lw=0.6)
        ax.set_title(f"class {c}: {pick['date']}\nD = {pick['D']:.2f}, K_T = {pick['K_T']:.2f}")
        ax.set_xlim(0, 24)
        ax.set_xticks(range(0, 25, 6))
    axes[0].set_ylabel("GHI (W/m$^2$)")
    fig.tight_layout()
    p = out / "fig1_example_days.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    written.append(p)

    m = monthly_d_table(res)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for year, g in m.groupby("year"):
        ax.plot(g["month"], g["mean_D"], marker="o", label=str(year))
    ax.set_xticks(range(1, 13))
    ax.set_xlabel("month")
    ax.set_ylabel("monthly mean D")
    ax.legend()
    fig.tight_layout()
    p = out / "fig2_monthly_D.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    written.append(p)
    return written
