"""Plausibility of a classified record: irradiance unit, site and clock.

None of these mistakes fails the classifier: GHI in kW/m2 makes every day overcast, a wrong
latitude sign gives K_T over 1, and local stamps read as UTC or a wrong longitude sign turn
clear days into partly cloudy ones.  The checks judge *daily aggregates* (a sample's GHI
may exceed the clear sky under cloud enhancement; a day's may not exceed the top of the
atmosphere) and, for the clock, a statistic over days (a cloudy day's light can peak at
any hour).  Thresholds and the reasons for them: docs/skytype.md, "Plausibility checks".

=================  =======  =====================================================================
check              kind     fires when
=================  =======  =====================================================================
``units``          error    every day with H0 >= 2 MJ/m2 has K_T < 0.02 and no GHI exceeds 2:
                            the values are kW/m2
``dark``           warning  every such day has K_T < 0.02 but GHI exceeds 2 (covered or dead
                            sensor, wrong column)
``site``           error    the median K_T of the kept days with H0 >= 2 MJ/m2 is over 1.0
``bright-day``     warning  some of those days have K_T over 1.2 (the median is not)
``night``          error    median over days with 6 h of samples: 30 min or more a day of GHI
                            over 20 W/m2 while the sun is computed 3 deg below the horizon
``clock``          warning  3 or more days of 6 h: both edges of the day's light (GHI over
                            10 W/m2) sit 0.5 h or more (median over days) on the same side of
                            the computed sunrise and sunset, and 2/3 of the days agree
``clock``          error    the same, 0.75 h or more
``clock``          warning  otherwise, 2 or more clear days (:mod:`.clear_shift`): their light,
                            fitted by a clear-sky shape shifted in time, comes 0.5 h or more
                            (median) after or before the computed sun; error from 0.75 h
=================  =======  =====================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

if TYPE_CHECKING:
    from controller.sun.source import Site

    from .classify import DayResults

#: K_T under this on every day is no sky (the darkest overcast days give 0.03-0.05).
KT_UNITS_MAX = 0.02
#: GHI in kW/m2 stays under this; W/m2 data of a day with H0 >= 2 MJ/m2 goes far over it.
KW_GHI_MAX = 2.0
#: Days of lower extraterrestrial irradiation (the edge of polar night) are not judged on K_T:
#: a few W/m2 of twilight there is a large share of H0.
H0_MIN_MJ = 2.0
#: The median daily K_T over this is the ground receiving more than the top of the atmosphere.
KT_SITE_MAX = 1.0
#: A single day over this is named in a warning (spikes, a wrong value).
KT_DAY_MAX = 1.2
#: "Night": the sun computed this far below the horizon (refraction lifts it 0.6 deg; the
#: analytic geometry is good to 0.3 deg; twilight GHI here is a few W/m2 at most).
NIGHT_ELEVATION_DEG = -3.0
#: GHI over this at night is daylight the geometry does not see.
NIGHT_GHI_W_M2 = 20.0
#: A slot is lit, for the edges of the day's light, over this GHI (sensor offsets stay under
#: it; an overcast sky passes it with the sun a few degrees up).
EDGE_GHI_W_M2 = 10.0
#: Lit night on the median day of at least this long, s.
LIT_NIGHT_S = 1800.0
#: Days with less than this of samples are not judged on lit night or the clock, s.
MIN_VALID_S = 6 * 3600.0
#: The clock: how far both edges of the day's light sit from the computed sunrise and sunset
#: (median over days) for a warning and for an error, h; the days needed; the share of the
#: days that must lie on the offset's side.
CLOCK_WARN_H = 0.5
CLOCK_ERROR_H = 0.75
CLOCK_MIN_DAYS = 3
CLOCK_SHARE = 2.0 / 3.0
#: Clear days (:mod:`.clear_shift`) that time the light when its edges cannot (a midnight sun).
CLOCK_MIN_CLEAR_DAYS = 2


@dataclass(frozen=True)
class Finding:
    """One thing a plausibility check found.

    Attributes
    ----------
    check : str
        ``units``, ``dark``, ``site``, ``bright-day``, ``night`` or ``clock``.
    error : bool
        True: the classes cannot be trusted (the command refuses); False: a warning.
    message : str
        One line: what was measured, and what is probably wrong.
    """

    check: Literal["units", "dark", "site", "bright-day", "night", "clock"]
    error: bool
    message: str


def light_centre_rows(
    ghi: np.ndarray, valid: np.ndarray, t0: np.ndarray, step_s: int, longitude: float, eot_s: np.ndarray
) -> np.ndarray:
    """Circular GHI-weighted mean hour angle of each row, as hours after solar noon.

    Parameters
    ----------
    ghi, valid : numpy.ndarray, shape (rows, n)
        GHI (W/m2; negatives count as 0) and the slots that hold a sample.
    t0 : numpy.ndarray, shape (rows,)
        POSIX time of slot 0, s.
    step_s : int
        Slot spacing, s.
    longitude : float
        Degrees east.
    eot_s : numpy.ndarray, shape (rows,)
        Equation of time, s.

    Returns
    -------
    numpy.ndarray, shape (rows,)
        Hours in (-12, 12]: positive when the row's light comes after solar noon; NaN for a
        row without light.  Circular, so a day split across the row's ends (stamps half a
        day off) still gives its centre.
    """
    rows, n = ghi.shape
    w = np.where(valid, np.maximum(ghi, 0.0), 0.0).astype(np.float64)
    a = (2.0 * np.pi * step_s / 86400.0) * np.arange(n)
    s_, c_ = w @ np.sin(a), w @ np.cos(a)
    # hour angle of slot 0 (as in cos_zenith_rows): the rows' phase b; sum w e^{i(a + b)}
    ast0 = (np.asarray(t0, float) + longitude * 240.0 + eot_s) / 86400.0
    b = 2.0 * np.pi * (ast0 - np.floor(ast0)) - np.pi
    sin_sum = np.cos(b) * s_ + np.sin(b) * c_
    cos_sum = np.cos(b) * c_ - np.sin(b) * s_
    off = np.arctan2(sin_sum, cos_sum) * (12.0 / np.pi)
    return np.where(w.sum(axis=1) > 0, off, np.nan)


def light_edge_rows(lit: np.ndarray, up: np.ndarray, step_s: int) -> np.ndarray:
    """How far both edges of each row's lit period sit from the computed sunrise and sunset.

    Parameters
    ----------
    lit : numpy.ndarray of bool, shape (rows, n)
        Slots with GHI over :data:`EDGE_GHI_W_M2`.
    up : numpy.ndarray of bool, shape (rows, n)
        Slots with the sun computed above the horizon.
    step_s : int
        Slot spacing, s.

    Returns
    -------
    numpy.ndarray, shape (rows,)
        Hours: the mean of the two edges' offsets when both moved the same way (a clock or
        longitude error moves both), else 0 (weather, a covered dome or a high horizon moves
        one edge, or pulls both inwards); NaN for a row with no sunrise and sunset, or whose
        light touches its ends.  The edges are the 0.5 % and 99.5 % points of the lit slots,
        so that a stray spike at night does not move them.
    """
    n = lit.shape[1]
    cum = np.cumsum(lit, axis=1, dtype=np.int64)
    tot = cum[:, -1]
    on = np.argmax(cum > 0.005 * tot[:, None], axis=1)
    end = np.argmax(cum >= 0.995 * tot[:, None], axis=1)
    rise = np.argmax(up, axis=1)
    sets = n - 1 - np.argmax(up[:, ::-1], axis=1)
    ok = (tot > 0) & up.any(axis=1) & ~up[:, 0] & ~up[:, -1] & ~lit[:, 0] & ~lit[:, -1]
    d_on, d_end = (on - rise) * (step_s / 3600.0), (end - sets) * (step_s / 3600.0)
    off = np.where(np.sign(d_on) == np.sign(d_end), 0.5 * (d_on + d_end), 0.0)
    return np.where(ok, off, np.nan)


def _wrap_h(x):
    """Hours wrapped to (-12, 12]."""
    return 12.0 - np.mod(12.0 - np.asarray(x, float), 24.0)


@dataclass(frozen=True)
class NoonOffset:
    """Where the record's light sits relative to computed solar noon.

    Attributes
    ----------
    hours : float
        Robust centre (circular mean, then the median of the days' deviations from it) of
        the days' offsets, h after solar noon, in (-12, 12]; NaN without days.
    n_days : int
        Days judged.
    n_near : int
        Days on the same side of noon as ``hours`` and at least half as far.
    """

    hours: float
    n_days: int
    n_near: int


def noon_offset(offsets_h: np.ndarray) -> NoonOffset:
    """Robust centre of per-day offsets from solar noon (hours, any wrap)."""
    off = np.asarray(offsets_h, float)
    off = off[np.isfinite(off)]
    if off.size == 0:
        return NoonOffset(float("nan"), 0, 0)
    ang = off * (np.pi / 12.0)
    m = float(np.arctan2(np.sin(ang).mean(), np.cos(ang).mean()) * 12.0 / np.pi)
    m = float(_wrap_h(m + np.median(_wrap_h(off - m))))
    near = (np.sign(off) == np.sign(m)) & (np.abs(off) >= abs(m) / 2.0)
    return NoonOffset(m, int(off.size), int(near.sum()))


def _clock_cause(hours: float, longitude: float) -> str:
    """The likely causes of light ``hours`` after computed solar noon."""
    late = "late" if hours > 0 else "early"
    causes = []
    zone = round(hours * 2.0) / 2.0
    if abs(hours) > 10.5:  # half a day: the sign of the zone cannot be told
        return (
            f"the light comes {abs(hours):.1f} h from solar noon, at the site's night: local times "
            "of a zone near UTC+12 or UTC-12 without a zone (naive stamps are read as UTC), or "
            "a wrong --lon"
        )
    if abs(hours - zone) <= 0.25 and zone != 0:
        causes.append(f"local times of UTC{zone:+g} without a zone (naive stamps are read as UTC)")
    else:
        causes.append("stamps in a local zone read as UTC, or a clock that drifted")
    if abs(longitude) >= 3.75 and abs(float(_wrap_h(hours - 2.0 * longitude / 15.0))) <= 0.25:
        causes.insert(
            0, f"the longitude's sign (--lon {-longitude:g}? --lon {longitude:g} moves noon by this)"
        )
    else:
        causes.append("the longitude's sign")
    return f"the stamps look {abs(hours):.1f} h {late}: " + ", or ".join(causes)


def check_record(res: DayResults, site: Site) -> list[Finding]:
    """Plausibility checks of a classified record (module docstring).

    Parameters
    ----------
    res : DayResults
        From :func:`controller.sky.classify.analyse_grid` (uses ``res.rows``).
    site : Site
        The site the record was classified at.

    Returns
    -------
    list of Finding
        Errors first; empty when nothing looks wrong.
    """
    rows = res.rows
    if rows.empty:
        return []
    out: list[Finding] = []
    kt = rows["K_T"].to_numpy(float)
    h0 = rows["H0_MJ"].to_numpy(float)
    gmax = rows["ghi_max"].to_numpy(float)
    valid = rows["valid_s"].to_numpy(float)
    top = float(np.max(gmax)) if gmax.size else float("nan")
    lat, lon = site.latitude, site.longitude

    # units: daily aggregates with the sun well up
    sunny = np.isfinite(kt) & (h0 >= H0_MIN_MJ) & (valid > 0)
    if sunny.any() and np.all(kt[sunny] < KT_UNITS_MAX) and top > 0:
        k = kt[sunny]
        span = f"daily K_T {k.min():.4f}-{k.max():.4f}, while the darkest sky gives 0.03"
        if top <= KW_GHI_MAX:
            out.append(
                Finding(
                    "units",
                    True,
                    f"GHI looks like kW/m2 (values up to {top:.3g}; {span}): heliotrack wants W/m2; "
                    "give --irradiance-unit kW/m2",
                )
            )
            return out  # nothing else can be judged on these values
        out.append(
            Finding(
                "dark",
                False,
                f"GHI is far below what any sky gives ({span}; values up to {top:.3g} W/m2): "
                "a covered or dead pyranometer, the wrong column (--ghi-col), or another unit?",
            )
        )

    # site: the ground cannot receive more than the top of the atmosphere over a day
    kept = rows["kept"].to_numpy(bool) & sunny
    offset = noon_offset(rows["noon_offset_h"].to_numpy(float)[valid >= MIN_VALID_S])
    clock_hint = (
        f"; {_clock_cause(offset.hours, lon)}"
        if np.isfinite(offset.hours) and abs(offset.hours) >= 0.5
        else ""
    )
    if kept.any() and float(np.median(kt[kept])) > KT_SITE_MAX:
        k = kt[kept]
        out.append(
            Finding(
                "site",
                True,
                f"daily clearness K_T {k.min():.2f}-{k.max():.2f} (median {np.median(k):.2f}) is over 1, "
                f"more than the top of the atmosphere gives at latitude {lat:g}: check the "
                f"latitude's sign (--lat {-lat:g}?) or the stamps' zone{clock_hint}",
            )
        )
    elif kept.any() and np.any(kt[kept] > KT_DAY_MAX):
        bad = rows["date"].to_numpy()[kept][kt[kept] > KT_DAY_MAX]
        out.append(
            Finding(
                "bright-day",
                False,
                f"K_T over {KT_DAY_MAX:g} on {len(bad)} day(s) (e.g. {', '.join(map(str, bad[:3]))}), "
                "more than the top of the atmosphere gives: spikes or wrong values in the GHI?",
            )
        )

    # night: daylight where the computed sun is well below the horizon
    judged = valid >= MIN_VALID_S
    lit = rows["lit_night_s"].to_numpy(float)[judged]
    site_said = any(f.check == "site" for f in out)  # it names the latitude and the clock
    if lit.size and float(np.median(lit)) >= LIT_NIGHT_S and not site_said:
        polar = (rows["daylight_s"].to_numpy(float) <= 0) & (gmax > NIGHT_GHI_W_M2)
        where = (
            f"; {int(polar.sum())} of the days have no daylight at all at latitude {lat:g} "
            f"(polar night) yet GHI up to {np.max(gmax[polar]):.0f} W/m2"
            if polar.any()
            else ""
        )
        if clock_hint:
            cause = clock_hint[2:]
        else:
            cause = (
                f"the light is centred on solar noon ({offset.hours:+.1f} h), so the clock looks "
                f"right: check the latitude's sign (--lat {-lat:g}?) and the site"
            )
        out.append(
            Finding(
                "night",
                True,
                f"GHI over {NIGHT_GHI_W_M2:g} W/m2 for {np.median(lit) / 3600:.1f} h a day (median of "
                f"{lit.size} days) while the sun is computed more than {-NIGHT_ELEVATION_DEG:g} deg "
                f"below the horizon at --lat {lat:g} --lon {lon:g}{where}: {cause}",
            )
        )

    # clock: both edges of the day's light moved the same way from the computed sunrise and
    # sunset.  Weather moves one edge by minutes (an overcast morning passes 10 W/m2 with the
    # sun a few degrees higher) and the centre of the light by hours (an afternoon storm every
    # day: -1.2 h at 35.8 N), so the edges, not the centre, judge the clock.
    edge = noon_offset(rows["edge_offset_h"].to_numpy(float)[valid >= MIN_VALID_S])
    if (
        not any(f.error for f in out)
        and edge.n_days >= CLOCK_MIN_DAYS
        and abs(edge.hours) >= CLOCK_WARN_H
        and edge.n_near >= CLOCK_SHARE * edge.n_days
    ):
        error = abs(edge.hours) >= CLOCK_ERROR_H
        out.append(
            Finding(
                "clock",
                error,
                f"the day's light begins and ends {abs(edge.hours):.1f} h "
                f"{'later' if edge.hours > 0 else 'earlier'} than the sun rises and sets at "
                f"--lat {lat:g} --lon {lon:g} (median of {edge.n_days} days, {edge.n_near} of them "
                f"on that side): {_clock_cause(edge.hours, lon)}",
            )
        )
    # the same from the clear days' light against the sun's height all day: where the sun
    # grazes the horizon for hours, or never sets, the edges tell nothing (65 N in June: a
    # record an hour late passed).  A sensor tilted east or west moves it too (5 deg at 70 N
    # in June: 0.56 h), so that is named beside the clock.
    clear = noon_offset(rows["clear_shift_h"].to_numpy(float)[valid >= MIN_VALID_S])
    if (
        not any(f.error or f.check == "clock" for f in out)
        and clear.n_days >= CLOCK_MIN_CLEAR_DAYS
        and abs(clear.hours) >= CLOCK_WARN_H
        and clear.n_near >= CLOCK_SHARE * clear.n_days
    ):
        out.append(
            Finding(
                "clock",
                abs(clear.hours) >= CLOCK_ERROR_H,
                f"the clear days' light follows the sun's height {abs(clear.hours):.1f} h "
                f"{'later' if clear.hours > 0 else 'earlier'} than computed at --lat {lat:g} "
                f"--lon {lon:g} (median of {clear.n_days} clear days, {clear.n_near} of them on "
                f"that side): {_clock_cause(clear.hours, lon)}; or a pyranometer tilted "
                f"towards the {'west' if clear.hours > 0 else 'east'}",
            )
        )
    return sorted(out, key=lambda f: not f.error)
