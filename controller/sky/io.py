"""Reading irradiance records: plain CSV, and BSRN, MIDC, SURFRAD through pvlib.iotools.

CSV column guessing (case-insensitive, first rule that matches wins; give ``time_col``,
``ghi_col``, ``dni_col`` to override):

* time: a column named ``time``, ``timestamp``, ``datetime``, ``date_time``, ``time_utc``,
  ``timestamp_utc``, ``utc`` or ``date``; else the only column whose name contains
  ``time``.  Text times are ISO 8601 (a form like 01/06/2016 reads day first or month
  first and is not guessed; a time without a date is refused); naive times are taken as
  UTC, times with an offset are converted to UTC.  A numeric time column is read as POSIX seconds.
* GHI: ``ghi``, ``ghi_wm2``, ``global``, ``global_horizontal``, ``glob``, ``dw_solar``,
  ``swdown``; else the only column whose name contains ``ghi`` or ``global``.
* DNI (optional): ``dni``, ``dni_wm2``, ``direct``, ``direct_normal``, ``beam``; else the
  only column whose name contains ``dni``.

Empty or NaN irradiance cells are missing samples (station files use them for outages);
text that is not a number, values below -20 W/m2 (more than a thermopile's night offset)
or above 2000 W/m2, and unparsable times are errors that name the file, row and column.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd

from controller.errors import InputError

Format = Literal["csv", "bsrn", "midc", "surfrad"]

TIME_NAMES = ("time", "timestamp", "datetime", "date_time", "time_utc", "timestamp_utc", "utc", "date")
GHI_NAMES = ("ghi", "ghi_wm2", "global", "global_horizontal", "glob", "dw_solar", "swdown")
DNI_NAMES = ("dni", "dni_wm2", "direct", "direct_normal", "beam")
#: Most negative plausible irradiance (thermopile night offset), W/m2.
MIN_IRRADIANCE = -20.0
#: Largest plausible irradiance (above any cloud enhancement at the ground), W/m2.
MAX_IRRADIANCE = 2000.0
#: Plausible sample times, POSIX s (1900-01-01 .. 2200-01-01).
TIME_RANGE = (-2208988800.0, 7258118400.0)


@dataclass(frozen=True)
class Record:
    """An irradiance record read from one or more files.

    Attributes
    ----------
    times : numpy.ndarray
        POSIX seconds (UTC), float64.
    ghi : numpy.ndarray
        W/m2, NaN = missing.
    dni : numpy.ndarray or None
        W/m2, NaN = missing; None when the files have no DNI.
    latitude, longitude, altitude : float or None
        From the station metadata when the format carries it.
    sources : tuple of str
        The files read.
    """

    times: np.ndarray
    ghi: np.ndarray
    dni: np.ndarray | None
    latitude: float | None = None
    longitude: float | None = None
    altitude: float | None = None
    sources: tuple[str, ...] = ()


def _pick(
    columns: list[str],
    given: str | None,
    exact: tuple[str, ...],
    contains: tuple[str, ...],
    what: str,
    path: Path,
    required: bool = True,
) -> str | None:
    if given is not None:
        if given in columns:
            return given
        low = {c.lower(): c for c in columns}
        if given.lower() in low:
            return low[given.lower()]
        raise InputError(f"{path}: no column {given!r} for {what}; columns are {columns}")
    low = {c.strip().lower(): c for c in columns}
    for name in exact:
        if name in low:
            return low[name]
    hits = [c for c in columns if any(s in c.lower() for s in contains)]
    if len(hits) == 1:
        return hits[0]
    if not required:
        return None
    why = f"several candidates {hits}" if hits else "no column looks like it"
    raise InputError(
        f"{path}: cannot tell which column is {what} ({why}); columns are "
        f"{columns}; name it with --{what.split()[0].lower()}-col"
    )


def _irradiance(values: pd.Series, path: Path, column: str, row_offset: int) -> np.ndarray:
    num = pd.to_numeric(values, errors="coerce")
    text = values.astype(str).str.strip()
    bad = (
        num.isna().to_numpy()
        & values.notna().to_numpy()
        & ~text.str.lower().isin(["", "nan", "na", "n/a", "null"]).to_numpy()
    )
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{path}: row {i + row_offset}, column {column!r}: expected an "
            f"irradiance in W/m2, got {values.iloc[i]!r}"
        )
    arr = num.to_numpy(dtype=float)
    out_of_range = (arr < MIN_IRRADIANCE) | (arr > MAX_IRRADIANCE)
    if out_of_range.any():
        i = int(np.flatnonzero(out_of_range)[0])
        raise InputError(
            f"{path}: row {i + row_offset}, column {column!r}: expected an "
            f"irradiance between {MIN_IRRADIANCE:g} and {MAX_IRRADIANCE:g} W/m2, "
            f"got {arr[i]:g} ({int(out_of_range.sum())} such rows)"
        )
    return arr


_TIME_ONLY = re.compile(r"\d{1,2}:\d{2}(:\d{2}(\.\d+)?)?")


def _times(values: pd.Series, path: Path, column: str, row_offset: int) -> np.ndarray:
    if pd.api.types.is_numeric_dtype(values):
        t = values.to_numpy(dtype=float)
        bad = ~np.isfinite(t)
    else:
        try:
            parsed = pd.to_datetime(values, utc=True, format="ISO8601")
        except (ValueError, TypeError):
            # ISO 8601 only: pandas' guessing read 20/03/2024 day first and 01/04/2024
            # month first in one column, and a time without a date as today's
            parsed = pd.to_datetime(values, utc=True, errors="coerce", format="ISO8601")
            first = int(np.flatnonzero(parsed.isna().to_numpy())[0])
            text = str(values.iloc[first]).strip()
            if _TIME_ONLY.fullmatch(text):
                raise InputError(
                    f"{path}: row {first + row_offset}, column {column!r}: {text!r} is a time without a "
                    "date (a date in another column?): give one column of date and time, e.g. "
                    "2016-06-01T12:00:00Z"
                ) from None
            raise InputError(
                f"{path}: row {first + row_offset}, column {column!r}: expected an ISO 8601 time "
                f"(2016-06-01T12:00:00Z, or 2016-06-01 12:00 as UTC), got {text!r}: a form like "
                "01/06/2016 reads day first or month first, so it is not guessed"
            ) from None
        # pandas reads "now" and "today" as the clock's present: not a sample time
        relative = values.astype(str).str.strip().str.lower().isin(["now", "today"]).to_numpy()
        bad = parsed.isna().to_numpy() | relative
        t = np.where(bad, np.nan, parsed.to_numpy(dtype="datetime64[ns]").astype(np.int64) / 1e9)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{path}: row {i + row_offset}, column {column!r}: expected a UTC time "
            f"(e.g. 2016-06-01T12:00:00Z), got {values.iloc[i]!r}"
        )
    far = (t < TIME_RANGE[0]) | (t > TIME_RANGE[1])
    if far.any():
        i = int(np.flatnonzero(far)[0])
        v = values.iloc[i]
        got = repr(v) if isinstance(v, str) else f"{float(v):g}"
        raise InputError(
            f"{path}: row {i + row_offset}, column {column!r}: expected a time "
            f"between the years 1900 and 2200 (POSIX seconds or ISO 8601), got {got}"
        )
    return t


def read_csv_record(
    path: str | Path, time_col: str | None = None, ghi_col: str | None = None, dni_col: str | None = None
) -> Record:
    """Read a CSV file with a UTC time column, a GHI column and optionally DNI (see module doc)."""
    path = Path(path)
    try:
        with warnings.catch_warnings():
            # a first row longer than the header: pandas would take its leading fields as
            # an index and shift every column (index_col=False only warns), so refuse it
            warnings.simplefilter("error", pd.errors.ParserWarning)
            df = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, index_col=False)
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except pd.errors.ParserWarning:
        raise InputError(f"{path}: row 2: more fields than the header (row 1) names") from None
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable CSV file ({str(exc).strip()})") from None
    if df.empty:
        raise InputError(f"{path}: no data rows (expected a header and one row per sample)")
    cols = [str(c) for c in df.columns]
    tc = _pick(cols, time_col, TIME_NAMES, ("time",), "time column", path)
    gc = _pick(cols, ghi_col, GHI_NAMES, ("ghi", "global"), "GHI column", path)
    dc = _pick(cols, dni_col, DNI_NAMES, ("dni",), "DNI column", path, required=dni_col is not None)
    assert tc is not None and gc is not None  # required: _pick raised otherwise
    # rows as the user sees them in an editor: header is row 1
    raw_t = df[tc].replace("", np.nan)
    numeric_t = pd.to_numeric(raw_t, errors="coerce")
    t_values = numeric_t if numeric_t.notna().all() else raw_t
    t = _times(t_values, path, tc, 2)
    ghi = _irradiance(df[gc].replace("", np.nan), path, gc, 2)
    dni = None if dc is None else _irradiance(df[dc].replace("", np.nan), path, dc, 2)
    return Record(times=t, ghi=ghi, dni=dni, sources=(str(path),))


def _merged_midc_map() -> dict[str, str]:
    from pvlib.iotools.midc import MIDC_VARIABLE_MAP

    merged: dict[str, str] = {}
    for mapping in MIDC_VARIABLE_MAP.values():
        merged.update(mapping)
    return merged


def read_station_record(
    path: str | Path, fmt: Format, ghi_col: str | None = None, dni_col: str | None = None
) -> Record:
    """Read a BSRN, MIDC or SURFRAD file with pvlib.iotools; columns mapped to ghi / dni."""
    import pvlib

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found")
    meta: dict = {}
    try:
        if fmt == "bsrn":
            data, meta = pvlib.iotools.read_bsrn(path)
        elif fmt == "surfrad":
            data, meta = pvlib.iotools.read_surfrad(path)
        elif fmt == "midc":
            data = pvlib.iotools.read_midc(path, variable_map=_merged_midc_map())
        else:
            raise InputError(f"{path}: unknown format {fmt!r} (csv, bsrn, midc, surfrad)")
    except InputError:
        raise
    except Exception as exc:  # pvlib raises many kinds on a malformed file
        raise InputError(f"{path}: not a readable {fmt.upper()} file ({type(exc).__name__}: {exc})") from None
    if data is None or len(data) == 0:
        raise InputError(f"{path}: the {fmt.upper()} file holds no data rows")
    cols = [str(c) for c in data.columns]
    gc = _pick(cols, ghi_col, ("ghi",), ("ghi", "global"), "GHI column", path)
    assert gc is not None  # required: _pick raised otherwise
    dni_candidates = ("dni", "dni_chp1", "dni_nip", "dni_rsp")
    dc = dni_col if dni_col is not None else next((c for c in dni_candidates if c in cols), None)
    if dc is not None and dc not in cols:
        raise InputError(f"{path}: no column {dc!r} for DNI; columns are {cols}")
    idx = pd.DatetimeIndex(data.index)
    if idx.tz is None:
        idx = idx.tz_localize("UTC")
    t = idx.tz_convert("UTC").as_unit("ns").asi8 / 1e9
    ghi = _irradiance(data[gc].reset_index(drop=True), path, gc, 1)
    dni = None if dc is None else _irradiance(data[dc].reset_index(drop=True), path, dc, 1)

    def meta_float(*keys: str) -> float | None:
        for k in keys:
            if isinstance(meta, dict) and meta.get(k) is not None:
                try:
                    return float(meta[k])
                except (TypeError, ValueError):
                    pass
        return None

    return Record(
        times=t,
        ghi=ghi,
        dni=dni,
        latitude=meta_float("latitude"),
        longitude=meta_float("longitude"),
        altitude=meta_float("altitude", "elevation"),
        sources=(str(path),),
    )


def read_records(
    paths: list[str | Path],
    fmt: Format = "csv",
    time_col: str | None = None,
    ghi_col: str | None = None,
    dni_col: str | None = None,
    progress: bool = False,
) -> Record:
    """Read and concatenate several files of one station (e.g. monthly BSRN files).

    DNI is kept only when every file has it.
    """
    if not paths:
        raise InputError("no input files given")
    it = paths
    if progress and len(paths) > 1:
        from tqdm import tqdm

        it = tqdm(paths, unit="file", desc="read")
    recs = [
        read_csv_record(p, time_col, ghi_col, dni_col)
        if fmt == "csv"
        else read_station_record(p, fmt, ghi_col, dni_col)
        for p in it
    ]
    if np.all(np.isnan(np.concatenate([r.ghi for r in recs]))):
        raise InputError(f"{', '.join(r.sources[0] for r in recs)}: every GHI value is missing")
    with_dni = all(r.dni is not None for r in recs)
    first = recs[0]
    for r in recs[1:]:  # one station: files of two would be averaged into one
        for a, b, what in (
            (first.latitude, r.latitude, "latitude"),
            (first.longitude, r.longitude, "longitude"),
        ):
            if a is not None and b is not None and abs(a - b) > 0.01:
                raise InputError(
                    f"{r.sources[0]}: {what} {b:g}, but {first.sources[0]} says {a:g}: "
                    "the files of one run are one station's"
                )
    return Record(
        times=np.concatenate([r.times for r in recs]),
        ghi=np.concatenate([r.ghi for r in recs]),
        dni=np.concatenate([r.dni for r in recs]) if with_dni else None,
        latitude=first.latitude,
        longitude=first.longitude,
        altitude=first.altitude,
        sources=tuple(s for r in recs for s in r.sources),
    )
