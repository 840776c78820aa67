"""``heliotrack sunpath``: learn the sun's path from observations, or predict it.

Two modes, chosen by the first positional argument::

    heliotrack sunpath OBS.csv [--method seed|kalman] [--lat DEG --lon DEG]
                               [--utc-offset HOURS] [--out FILE] [--state FILE]
                               [--fit mirrored|whole-day] [--chain-prior]
    heliotrack sunpath predict [OBS.csv] [--state FILE] [--lat DEG --lon DEG]
                               (--at TIME ... | --start TIME --end TIME [--step-min M])

The first writes one row per day (date, noon_utc, noon_el_deg, declination_deg, lat_deg,
lon_deg, n_obs, method, ...) as CSV, or as JSON lines when ``--out`` ends in .jsonl/.json
or ``--format jsonl``.  ``predict`` runs the Kalman filter over OBS.csv and/or a saved
state and prints time, az_deg, el_deg and one-sigma for each requested time.  (A file
literally named ``predict`` must be given as ``./predict``.)
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from datetime import UTC, datetime
from pathlib import Path

from heliotrack.argtypes import LATITUDE, LONGITUDE, number_in

#: The most times ``predict --start/--end`` writes (a year at one-minute steps).
MAX_STEPS = 600_000
#: More than this share of the observations rejected is warned about (clouds, reflections
#: and a sensor's distractors reject some: normal).
REJECTED_WARN_FRACTION = 0.5
#: The seed's ``--noon-elevation vertex`` reads noon 1-6 deg low, and its latitude as far
#: off: only a latitude further than this from --lat is a mistake there.
VERTEX_LAT_TOL_DEG = 10.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sunpath",
        help="learn the sun's path from observations (seed or Kalman), or predict",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "inputs",
        nargs="+",
        metavar="[predict] OBS.csv",
        help="observation CSV (time, az_deg, el_deg[, sigma_deg]); 'predict' first for prediction mode",
    )
    p.add_argument(
        "--method",
        choices=("seed", "kalman"),
        default="kalman",
        help="seed: the paper's daily parabola; kalman: the sun-path EKF (default)",
    )
    p.add_argument("--lat", type=LATITUDE, default=None, help="site latitude, deg north")
    p.add_argument("--lon", type=LONGITUDE, default=None, help="site longitude, deg east")
    p.add_argument(
        "--utc-offset",
        type=number_in(-14.0, 14.0),
        default=None,
        metavar="HOURS",
        help="local civil offset used to group days (default: from the data)",
    )
    p.add_argument(
        "--declination",
        choices=("ephemeris", "free"),
        default="ephemeris",  # = KalmanConfig().declination (tested)
        help="kalman: SPA's declination plus a learnt correction (ephemeris, "
        "default; needs only UTC) or declination learnt from the sky alone "
        "through the orbit law (free; the mode that measures declination)",
    )
    p.add_argument(
        "--noon-elevation",
        choices=("measured", "vertex"),
        default="measured",
        help="seed: Elv_n is the elevation measured at the transit (the paper, "
        "default: the observation within half a sampling interval of the "
        "fitted noon, else none that day) or the parabola's vertex value "
        "(a labelled variant, biased by degrees over a whole day)",
    )
    p.add_argument(
        "--fit",
        choices=("mirrored", "whole-day"),
        default="mirrored",
        help="seed: each day's parabola on the samples mirrored about the fitted "
        "noon, iterated (default; the paper's 'before to after solar noon') "
        "or on every sample of the day (a labelled variant, biased by the "
        "window's position about noon)",
    )
    p.add_argument(
        "--chain-prior",
        action="store_true",
        help="seed: fit each day with yesterday's parabola as prior (a labelled "
        "variant; the paper uses the prior only to predict, and each day's "
        "noon is that day's own fit)",
    )
    p.add_argument(
        "--window-h",
        type=number_in(0.0, 12.0, open_lo=True),
        default=None,
        help="seed: fit only observations within this many hours of noon",
    )
    p.add_argument(
        "--state",
        type=Path,
        default=None,
        help="kalman: learned state file, loaded if present and saved after",
    )
    p.add_argument("--out", type=Path, default=None, help="output file (default stdout)")
    p.add_argument(
        "--format",
        choices=("csv", "jsonl"),
        default=None,
        help="output format (default from --out suffix, else csv)",
    )
    p.add_argument(
        "--at",
        action="append",
        default=[],
        metavar="TIME",
        help="predict: ISO 8601 time with offset (repeatable)",
    )
    p.add_argument("--start", default=None, help="predict: first time (ISO 8601)")
    p.add_argument("--end", default=None, help="predict: last time (ISO 8601)")
    p.add_argument(
        "--step-min", type=number_in(0.0, 1440.0, open_lo=True), default=15.0, help="predict: step, minutes"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from controller.errors import InputError

    if (args.lat is None) != (args.lon is None):
        raise InputError("sunpath: give both --lat and --lon, or neither")
    if args.lat is not None and not (-90 <= args.lat <= 90 and -180 <= args.lon <= 360):
        raise InputError("sunpath: --lat must be in [-90, 90] and --lon in [-180, 360]")
    _check_out(args)
    if args.inputs[0] == "predict":
        if len(args.inputs) > 2:
            raise InputError("sunpath predict: expected at most one OBS.csv")
        return _predict(args, Path(args.inputs[1]) if len(args.inputs) == 2 else None)
    if len(args.inputs) != 1:
        raise InputError("sunpath: expected one OBS.csv (or 'predict ...')")
    return _fit(args, Path(args.inputs[0]))


def _site(args):
    from controller.sun.source import Site

    return None if args.lat is None else Site(args.lat, ((args.lon + 180) % 360) - 180)


def _kalman(args, obs, source: str):
    from controller.sunpath.batch import run_kalman
    from controller.sunpath.kalman import KalmanConfig, SunPathKalman
    from controller.sunpath.state import load_state, save_state

    kf = load_state(args.state) if args.state is not None else None
    if kf is None:
        kf = SunPathKalman(KalmanConfig(declination=args.declination), _site(args))
    else:
        _same_site(kf, args)
        obs = _not_yet_absorbed(kf, obs or [], args.state)
    rejected = kf.n_rejected
    rows, kf = run_kalman(obs or [], utc_offset_h=args.utc_offset, kf=kf)
    _sky_fits_site(kf, args, source, len(obs or []), kf.n_rejected - rejected)
    if args.state is not None and (obs or args.state.exists()):  # nothing learned: no new file
        save_state(args.state, kf)
    return rows, kf


def _sky_fits_site(kf, args, source: str, n_obs: int, n_rejected: int) -> None:
    """A sky that fits a site far from --lat/--lon is an error, before anything is written
    (it had exited 0 with every observation rejected and the given site's ephemeris as
    its rows); most observations rejected without a measured offset is a warning."""
    from controller.errors import InputError
    from controller.sunpath.ephemeris import wrap180

    site, m = _site(args), kf.site_mismatch
    if site is not None and m is not None:
        sky_lat, sky_lon = site.latitude + m.lat_offset_deg, float(wrap180(site.longitude + m.lon_offset_deg))
        raise InputError(
            f"{source}: the sky does not fit --lat {args.lat:g} --lon {args.lon:g}: {n_rejected} of "
            f"{n_obs} observations rejected, and they fit a site at lat {sky_lat:.2f}, lon {sky_lon:.2f} "
            f"(offset {m.lat_offset_deg:+.2f} deg in latitude, {m.lon_offset_deg:+.2f} deg in longitude): "
            f"{m.likely_cause(site, kf.config.site_mismatch_deg)}; nothing written"
        )
    if n_obs and n_rejected > REJECTED_WARN_FRACTION * n_obs:
        why = (
            "the sky may not fit --lat/--lon (too few in a row to measure how far off): check their "
            "signs (north and east positive) and the time stamps' zone"
            if site is not None
            else "not one sun's path: check the times' zone and the sensor"
        )
        print(
            f"heliotrack: warning: {source}: {n_rejected} of {n_obs} observations rejected: {why}",
            file=sys.stderr,
        )


def _seed_fits_site(rows, args, source: str) -> None:
    """The seed method's own site (latitude from each day's noon elevation, longitude from
    its noon time) far from --lat/--lon is an error, before anything is written, as for the
    Kalman filter: it had printed a declination of 75 deg for a latitude given with the
    wrong sign, without a word."""
    import numpy as np

    from controller.errors import InputError
    from controller.sunpath.ephemeris import wrap180
    from controller.sunpath.kalman_config import KalmanConfig
    from controller.sunpath.recovery import SiteMismatch

    site = _site(args)
    lats = [r.lat_deg for r in rows if np.isfinite(r.lat_deg)]
    lons = [r.lon_deg for r in rows if np.isfinite(r.lon_deg)]
    if site is None or not lats or not lons:
        return
    dlat = float(np.median(lats)) - site.latitude
    dlon = float(wrap180(float(np.median(lons)) - site.longitude))
    tol = KalmanConfig().site_mismatch_deg
    if args.noon_elevation == "vertex" and abs(dlat) <= VERTEX_LAT_TOL_DEG:
        dlat = 0.0  # that variant's latitude is biased by its design, not by a mistake
    if max(abs(dlat), abs(dlon)) > tol:
        m = SiteMismatch(dlat, dlon, rows[-1].noon_utc)
        raise InputError(
            f"{source}: the sky does not fit --lat {args.lat:g} --lon {args.lon:g}: its {len(rows)} "
            f"day(s) put the site at lat {site.latitude + dlat:.2f}, lon "
            f"{float(wrap180(site.longitude + dlon)):.2f} (median; offset {dlat:+.2f} deg in latitude, "
            f"{dlon:+.2f} deg in longitude): {m.likely_cause(site, tol)}; nothing written"
        )


def _not_yet_absorbed(kf, obs: list, state: Path) -> list:
    """The observations after the time the state refers to: one fed again (the same file
    run twice into one --state) would count twice and shrink the sigmas each time."""
    if kf.t is None:
        return obs
    new = [o for o in obs if o.time > kf.t]
    if len(new) < len(obs):
        from controller.timestamps import to_iso

        print(
            f"heliotrack: warning: {len(obs) - len(new)} observation(s) at or before {to_iso(kf.t)}, "
            f"the time {state} refers to, skipped: the state has them already",
            file=sys.stderr,
        )
    return new


def _same_site(kf, args) -> None:
    """A state learned at another site than --lat/--lon say is an error (it had been
    followed silently: a prediction for the state's site, not the one asked for)."""
    from controller.errors import InputError
    from controller.sunpath.state import learned_site

    site = learned_site(kf)
    if args.lat is None or site is None:
        return
    lat, lon = site
    dlon = (lon - args.lon + 180.0) % 360.0 - 180.0
    if max(abs(lat - args.lat), abs(dlon)) > kf.config.site_mismatch_deg:
        raise InputError(
            f"{args.state}: learned at lat {lat:.4f}, lon {lon:.4f}; --lat/--lon say {args.lat:g}, "
            f"{args.lon:g} (over {kf.config.site_mismatch_deg:g} deg away): give this site's state, or none"
        )


def _fit(args, path: Path) -> int:
    from controller.sunpath.io import read_observations
    from controller.sunpath.parabola import run_seed

    obs = read_observations(path)
    if args.utc_offset is not None:
        from controller.sunpath.days import misplaced_noon

        warning = misplaced_noon([o.time for o in obs], [o.el_deg for o in obs], args.utc_offset)
        if warning:
            print(f"heliotrack: warning: {warning}", file=sys.stderr)
    if args.method == "seed":
        rows, _ = run_seed(
            [o.time for o in obs],
            [o.az_deg for o in obs],
            [o.el_deg for o in obs],
            args.utc_offset,
            lat_deg=args.lat,
            window_h=args.window_h,
            noon_elevation=args.noon_elevation,
            fit=args.fit,
            use_prior=args.chain_prior,
        )
        _seed_fits_site(rows, args, str(path))
    else:
        rows, kf = _kalman(args, obs, str(path))
        if not kf.initialised:
            print(
                "heliotrack: warning: the Kalman filter could not start from these "
                f"observations (need {kf.config.init_min_obs} spanning "
                f"{kf.config.init_min_span_h} h, or --lat/--lon)",
                file=sys.stderr,
            )
    why = None
    if args.method == "seed" and not rows:
        from controller.sunpath.days import why_no_noon

        why = why_no_noon([o.time for o in obs], [o.el_deg for o in obs], args.utc_offset)
    _write([r.as_row() for r in rows], args, why)
    return 0


def _predict(args, path: Path | None) -> int:
    import numpy as np

    from controller.errors import InputError
    from controller.sun.source import EphemerisSource
    from controller.sunpath.io import parse_time, read_observations

    times = [parse_time(s, f"--at {s!r}") for s in args.at]
    if args.start is not None or args.end is not None:
        if args.start is None or args.end is None or args.step_min <= 0:
            raise InputError("sunpath predict: --start and --end go together, with --step-min > 0")
        t0, t1 = parse_time(args.start, "--start"), parse_time(args.end, "--end")
        if t1 < t0:
            raise InputError("sunpath predict: --end is before --start")
        n = (t1 - t0) / (args.step_min * 60.0)
        if n > MAX_STEPS:
            raise InputError(f"sunpath predict: {n:.0f} steps from --start to --end; at most {MAX_STEPS}")
        times.extend(np.arange(t0, t1 + 1e-6, args.step_min * 60.0).tolist())
    if not times:
        raise InputError("sunpath predict: give --at TIME or --start/--end")
    obs = read_observations(path) if path is not None else []
    kf = None
    if obs or args.state is not None:
        _, kf = _kalman(args, obs, str(path) if path is not None else str(args.state))
    rows = []
    eph = EphemerisSource(_site(args)) if args.lat is not None else None
    if (kf is None or not kf.initialised) and eph is None:
        raise InputError(
            "sunpath predict: nothing to predict from: the filter has not "
            "started (give more observations, --state, or --lat/--lon)"
        )
    for t in times:
        if kf is not None and kf.initialised:
            p = kf.predict(t)
            az, el, cov, src = p.az_deg, p.el_deg, p.covariance, "predicted"
        else:
            assert eph is not None  # checked above: no filter means a site was given
            e = eph.estimate(t)
            az, el, cov, src = e.az_deg, e.el_deg, e.covariance, "ephemeris"
        rows.append(
            {
                "time": datetime.fromtimestamp(t, tz=UTC).isoformat(timespec="seconds"),
                "az_deg": round(float(az), 6),
                "el_deg": round(float(el), 6),
                "sigma_az_deg": round(float(np.sqrt(cov[0, 0])), 6),
                "sigma_el_deg": round(float(np.sqrt(cov[1, 1])), 6),
                "source": src,
            }
        )
    _write(rows, args)
    return 0


def _check_out(args) -> None:
    """``--out`` must be a file that can be written: checked before the work."""
    from controller.errors import InputError

    out = args.out
    if out is None:
        return
    if out.is_dir():
        raise InputError(f"--out: {out} is a folder; give the file to write")
    if not out.parent.is_dir():
        raise InputError(f"--out: {out.parent} is not a folder that exists")


def _write(rows: list[dict], args, why: str | None = None) -> None:
    if not rows:  # an empty file written over the user's would say nothing, and lose it
        detail = f": {why}" if why else ""
        print(f"heliotrack: warning: no row to write (no day could be fitted{detail})", file=sys.stderr)
        return
    fmt = args.format or (
        "jsonl" if args.out is not None and args.out.suffix.lower() in (".jsonl", ".json") else "csv"
    )
    buf = io.StringIO()
    if fmt == "jsonl":
        for r in rows:
            buf.write(json.dumps(r) + "\n")
    elif rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    if args.out is None:
        sys.stdout.write(buf.getvalue())
    else:
        from controller.atomic import atomic_write

        atomic_write(args.out, buf.getvalue())
