"""Reading sun observations and request times from CSV, with errors that say what to fix.

Observation CSV: a header with ``time`` (ISO 8601 with a UTC offset, e.g.
``2024-03-01T08:15:00+03:30`` or ``...Z``), ``az_deg`` (clockwise from north),
``el_deg`` (above the horizon) and optionally ``sigma_deg`` (one-sigma, > 0; default 0.3).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

from ..errors import InputError
from ..sun.types import SunObservation
from ..timestamps import parse_timestamp

REQUIRED = ("time", "az_deg", "el_deg")
DEFAULT_SIGMA_DEG = 0.3


def parse_time(text: str, where: str) -> float:
    """Time with a zone -> POSIX seconds (:func:`controller.timestamps.parse_timestamp`)."""
    return parse_timestamp(text, where, require_zone=True)


def _number(text: str | None, where: str, lo: float, hi: float, what: str) -> float:
    try:
        v = float(text)  # type: ignore[arg-type]  # None (a short row) -> TypeError below
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected {what}, got {text!r}") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise InputError(f"{where}: expected {what}, got {text!r}")
    return v


def read_observations(path: str | Path, sensor: str = "csv") -> list[SunObservation]:
    """Read an observation CSV (see module docstring); observations come back time-sorted.

    Raises
    ------
    InputError
        Missing file or column, bad value (names file, row and column), or no rows.
    """
    path = Path(path)
    try:
        fh = path.open(newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(f"{path}: cannot read observations ({exc.strerror})") from None
    out = []
    with fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        reader.fieldnames = header
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise InputError(f"{path}: row 1 (header): missing column(s) {', '.join(missing)};"
                             f" expected time, az_deg, el_deg[, sigma_deg], got "
                             f"{', '.join(header) or 'nothing'}")
        for row_no, row in enumerate(reader, start=2):
            if not any((v or "").strip() for v in row.values() if isinstance(v, str)):
                continue  # blank line
            w = f"{path}: row {row_no}"
            t = parse_time(row.get("time") or "", f"{w}, column 'time'")
            az = _number(row.get("az_deg"), f"{w}, column 'az_deg'", -360.0, 720.0,
                         "an azimuth in degrees")
            el = _number(row.get("el_deg"), f"{w}, column 'el_deg'", -90.0, 90.0,
                         "an elevation in degrees between -90 and 90")
            sig_text = (row.get("sigma_deg") or "").strip() if "sigma_deg" in header else ""
            sig = (_number(sig_text, f"{w}, column 'sigma_deg'", 1e-6, 90.0,
                           "a positive one-sigma in degrees") if sig_text else DEFAULT_SIGMA_DEG)
            out.append(SunObservation(t, az % 360.0, el, sig, sensor=sensor))
    if not out:
        raise InputError(f"{path}: no observations (expected rows of time, az_deg, el_deg)")
    out.sort(key=lambda o: o.time)
    return out
