"""``heliotrack classify FILE...``: day types of an irradiance record (paper 002 and better)."""

from __future__ import annotations

import argparse
from pathlib import Path

from heliotrack.argtypes import ALTITUDE, LATITUDE, LONGITUDE, number_in

#: The fractal dimension of a day's curve lies in [1, 2] (SkyConfig.d_thresholds' range).
D_VALUE = number_in(1.0, 2.0)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "classify",
        help="classify days as clear / partly cloudy / overcast from GHI",
        description="Classify each day of a GHI record (I clear, II partly cloudy, III "
        "overcast) and write days.csv, the paper's tables and figures.",
    )
    p.add_argument("files", nargs="+", type=Path, metavar="FILE", help="input files, one station")
    p.add_argument("--lat", type=LATITUDE, help="latitude, deg north (required unless the file says)")
    p.add_argument("--lon", type=LONGITUDE, help="longitude, deg east (required unless the file says)")
    p.add_argument("--alt", type=ALTITUDE, default=None, help="altitude, m (default from file or 0)")
    p.add_argument("--format", choices=("csv", "bsrn", "midc", "surfrad"), default="csv")
    p.add_argument("--time-col", help="CSV time column (UTC); guessed if omitted")
    p.add_argument("--ghi-col", help="GHI column; guessed if omitted")
    p.add_argument("--dni-col", help="DNI column (adds the sunshine-duration truth)")
    p.add_argument(
        "--irradiance-unit",
        choices=("W/m2", "kW/m2"),
        default="W/m2",
        help="unit of the GHI and DNI values (default W/m2; values that look like kW/m2 are "
        "refused unless this says so)",
    )
    p.add_argument(
        "--settings",
        type=Path,
        default=None,
        help="TOML file with a [sky] table (docs/config.md); options below override it",
    )
    p.add_argument(
        "--method",
        choices=("default", "seed"),
        default=None,
        help="rule for the class column (seed: the paper's D and K_T rule; default: default)",
    )
    p.add_argument(
        "--threshold-rule",
        choices=("range", "tertiles", "fixed"),
        default=None,
        help="how the seed rule sets D_I, D_II per year (default: range)",
    )
    p.add_argument(
        "--d-thresholds",
        type=D_VALUE,
        nargs=2,
        metavar=("D_I", "D_II"),
        help="fixed D_I D_II (implies --threshold-rule fixed)",
    )
    p.add_argument(
        "--max-missing-min",
        type=float,
        default=None,
        help="exclude days with more daylight than this missing, min (default 60)",
    )
    p.add_argument("--out", type=Path, default=Path("skytype-out"), help="output directory")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys
    from dataclasses import replace

    from controller.errors import InputError
    from controller.schema import load_file
    from controller.sky.classify import analyse_grid
    from controller.sky.grid import build_day_grid
    from controller.sky.io import read_records
    from controller.sky.plausibility import check_record
    from controller.sky.settings import SkyConfig, SkySettings
    from controller.sun.source import Site
    from heliotrack.output import check_out_dir
    from heliotrack.reports.skytype import write_figures, write_tables

    progress = sys.stderr.isatty()
    rec = read_records(
        list(args.files), args.format, args.time_col, args.ghi_col, args.dni_col, progress=progress
    )
    lat = args.lat if args.lat is not None else rec.latitude
    lon = args.lon if args.lon is not None else rec.longitude
    if lat is None or lon is None:
        raise InputError("--lat and --lon are required (the input files do not give the site)")
    if not (-90 <= lat <= 90 and -180 <= lon <= 360):
        raise InputError(f"--lat/--lon out of range: {lat}, {lon}")
    alt = args.alt if args.alt is not None else (rec.altitude or 0.0)
    if args.irradiance_unit == "kW/m2":
        rec = _from_kw(rec)
    config = load_file(SkySettings, args.settings).sky if args.settings else SkyConfig()
    overrides: dict = {}
    if args.method is not None:
        overrides["method"] = args.method
    if args.max_missing_min is not None:
        if not 0 <= args.max_missing_min <= 1440:
            raise InputError(f"--max-missing-min: expected minutes in [0, 1440], got {args.max_missing_min}")
        overrides["max_missing_s"] = 60.0 * args.max_missing_min
    if args.d_thresholds:
        if args.d_thresholds[0] > args.d_thresholds[1]:
            # the seed rule reads D < D_I as clear and D > D_II as overcast: inverted, no day
            # would be partly cloudy and the two classes would overlap
            raise InputError(
                f"--d-thresholds: expected D_I <= D_II, got {args.d_thresholds[0]:g} {args.d_thresholds[1]:g}"
            )
        overrides.update(threshold_rule="fixed", d_thresholds=tuple(args.d_thresholds))
    elif args.threshold_rule is not None:
        overrides["threshold_rule"] = args.threshold_rule
    config = replace(config, **overrides)
    check_out_dir(args.out, "--out", files=(), folders=())  # before the analysis, not after it
    try:
        grid = build_day_grid(rec.times, rec.ghi, lon, dni=rec.dni)
    except ValueError as exc:
        raise InputError(f"{', '.join(rec.sources)}: {exc}") from None
    site = Site(lat, lon, alt)
    res = analyse_grid(grid, site, config, with_clearsky=rec.dni is not None, progress=progress)
    findings = check_record(res, site)  # before anything is written
    errors = [f.message for f in findings if f.error]
    if errors:
        raise InputError(f"{', '.join(rec.sources)}: " + "; and ".join(errors))
    for f in findings:
        print(f"heliotrack: warning: {', '.join(rec.sources)}: {f.message}", file=sys.stderr)
    if len(res.days) == 0:
        raise InputError(
            f"{', '.join(rec.sources)}: no day could be classified "
            f"({len(res.excluded)} excluded, e.g. {res.excluded['reason'].iloc[0] if len(res.excluded) else 'no data'})"
            + _contradiction(res)
        )
    written = write_tables(res, args.out) + write_figures(res, grid, args.out)
    counts = res.days["class"].value_counts()
    print(
        f"{len(res.days)} days classified ({config.method} rule, grid {res.step_s} s), "
        f"{len(res.excluded)} excluded: "
        + ", ".join(f"{c} {int(counts.get(c, 0))}" for c in ("I", "II", "III"))
    )
    if "truth" in res.days:
        agr = res.days[res.days["truth"] != ""]
        for col in ("class_default", "class_seed", "class_kt", "class_csd"):
            if col in agr and len(agr):
                print(
                    f"  agreement with sunshine truth, {col[6:]}: "
                    f"{100 * (agr[col] == agr['truth']).mean():.1f} % of {len(agr)} days"
                )
    print(f"wrote {len(written)} files to {args.out}")
    return 0


def _from_kw(rec):
    """The record with its irradiances in W/m2 (``--irradiance-unit kW/m2``)."""
    from dataclasses import replace

    import numpy as np

    from controller.errors import InputError

    top = float(np.nanmax(rec.ghi))
    if top > 2.0:  # 2 kW/m2 is more than the sun gives; the reader's W/m2 bound, scaled
        raise InputError(
            f"{', '.join(rec.sources)}: --irradiance-unit kW/m2, but GHI reaches {top:g}: "
            "these values look like W/m2 (leave the option out)"
        )
    return replace(rec, ghi=rec.ghi * 1000.0, dni=None if rec.dni is None else rec.dni * 1000.0)


def _contradiction(res) -> str:
    """Why a "no day" reason may be wrong: the site's night or missing daylight has light."""
    rows = res.rows
    if rows.empty:
        return ""
    from controller.sky.plausibility import LIT_NIGHT_S, NIGHT_GHI_W_M2

    # light on a day the site has none (polar night), or for half an hour where its sun is down
    dark = (rows["daylight_s"] <= 0) | (rows["lit_night_s"] >= LIT_NIGHT_S)
    lit = rows[~rows["kept"] & dark & (rows["ghi_max"] > NIGHT_GHI_W_M2)]
    if lit.empty:
        return ""
    return (
        f"; yet GHI reaches {lit['ghi_max'].max():.0f} W/m2 on {len(lit)} of those days where the "
        "computed sun is down: check the --lat/--lon signs and the stamps' zone (naive stamps "
        "are read as UTC)"
    )
