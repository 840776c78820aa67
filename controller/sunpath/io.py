"""Reading sun observations and request times, with errors that say what to fix.

Two forms, told apart by the first character:

* CSV: a header with ``time`` (a time with a zone, any form of
  :mod:`controller.timestamps`, e.g. ``2024-03-01T08:15:00+03:30`` or ``...Z``), ``az_deg``
  (clockwise from north), ``el_deg`` (above the horizon) and optionally ``sigma_deg``
  (one-sigma, > 0; default 0.3);
* JSON lines, as ``heliotrack estimate`` prints them: one object per line with ``found``,
  ``time``, ``az_deg``, ``el_deg``, ``sigma_deg`` and ``frame``; lines with ``found``
  false are skipped, so ``estimate ... > obs.jsonl`` feeds ``sunpath obs.jsonl`` directly.
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

from ..errors import InputError
from ..sun.types import SunObservation
from ..timestamps import parse_timestamp, to_iso

REQUIRED = ("time", "az_deg", "el_deg")
DEFAULT_SIGMA_DEG = 0.3


def read_text_strict(path: Path, what: str) -> str:
    """A file's text (UTF-8, with or without a BOM); an unreadable or non-UTF-8 file is an
    InputError naming the file and the line of the first bad byte."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what} ({exc.strerror})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(
            f"{path}: row {line}: not UTF-8 text (byte 0x{data[exc.start]:02x}); save the file as UTF-8"
        ) from None


def _read_json_lines(path: Path, text: str, sensor: str) -> list[SunObservation]:
    out: list[tuple[SunObservation, int]] = []
    skipped = 0
    for line_no, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        w = f"{path}: line {line_no}"
        try:
            d = json.loads(line)
        except json.JSONDecodeError as exc:
            raise InputError(f"{w}: not JSON ({exc.msg}, column {exc.colno})") from None
        if not isinstance(d, dict):
            raise InputError(f"{w}: expected a JSON object per line")
        found = d.get("found", False)
        if not isinstance(found, bool):  # "false", a string, is true
            raise InputError(f"{w}, key 'found': expected true or false, got {found!r}")
        if not found:
            skipped += 1
            continue
        if d.get("time") is None:
            raise InputError(
                f"{w}: found but without a time (give estimate --time, or name frames by their time)"
            )
        t = parse_time(str(d["time"]), f"{w}, key 'time'")
        az = _number(d.get("az_deg"), f"{w}, key 'az_deg'", -360.0, 720.0, "an azimuth in degrees")
        el = _number(
            d.get("el_deg"), f"{w}, key 'el_deg'", -90.0, 90.0, "an elevation in degrees between -90 and 90"
        )
        sig = d.get("sigma_deg")
        sig = (
            DEFAULT_SIGMA_DEG
            if sig is None
            else _number(sig, f"{w}, key 'sigma_deg'", 1e-6, 90.0, "a positive one-sigma in degrees")
        )
        frame = d.get("frame", "enu")
        if frame not in ("enu", "model"):
            raise InputError(f"{w}, key 'frame': expected enu or model, got {frame!r}")
        if frame == "enu":
            _seen(el, f"{w}, key 'el_deg'")
        out.append((SunObservation(t, az % 360.0, el, sig, frame=frame, sensor=sensor), line_no))
    if not out:
        raise InputError(f"{path}: no observations with found = true ({skipped} without)")
    return _time_ordered(out, path, "line")


#: The lowest elevation a sighting of the sun can have (deg): refraction and a high site's
#: dip of the horizon show it a little under 0, never further.
MIN_SEEN_EL_DEG = -2.0


def _seen(el: float, where: str) -> None:
    """Refuse a sighting of the sun further below the horizon than it can be seen: a night
    row, or another convention (a zenith angle, a sign)."""
    if el < MIN_SEEN_EL_DEG:
        raise InputError(
            f"{where}: {el:g} deg, a sun seen below the horizon (at least {MIN_SEEN_EL_DEG:g}); "
            "a night row, or a zenith angle or another sign convention?"
        )


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
    text = read_text_strict(path, "observations")
    if text.lstrip().startswith("{"):
        return _read_json_lines(path, text, sensor)
    out: list[tuple[SunObservation, int]] = []
    with io.StringIO(text, newline="") as fh:
        reader = csv.DictReader(fh)
        header = [h.strip() for h in (reader.fieldnames or [])]
        reader.fieldnames = header
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise InputError(
                f"{path}: row 1 (header): missing column(s) {', '.join(missing)};"
                f" expected time, az_deg, el_deg[, sigma_deg], got "
                f"{', '.join(header) or 'nothing'}"
            )
        for row_no, row in enumerate(reader, start=2):
            w = f"{path}: row {row_no}"
            if row.get(None):  # DictReader's key of the fields beyond the header
                # e.g. a decimal comma: "10,5" would shift el_deg into az_deg's neighbour
                raise InputError(
                    f"{w}: {len(header) + len(row[None])} fields, the header names "
                    f"{len(header)} (a decimal comma? use a point)"
                )
            if not any((v or "").strip() for v in row.values() if isinstance(v, str)):
                continue  # blank line
            t = parse_time(row.get("time") or "", f"{w}, column 'time'")
            az = _number(row.get("az_deg"), f"{w}, column 'az_deg'", -360.0, 720.0, "an azimuth in degrees")
            el = _number(
                row.get("el_deg"),
                f"{w}, column 'el_deg'",
                -90.0,
                90.0,
                "an elevation in degrees between -90 and 90",
            )
            _seen(el, f"{w}, column 'el_deg'")
            sig_text = (row.get("sigma_deg") or "").strip() if "sigma_deg" in header else ""
            sig = (
                _number(sig_text, f"{w}, column 'sigma_deg'", 1e-6, 90.0, "a positive one-sigma in degrees")
                if sig_text
                else DEFAULT_SIGMA_DEG
            )
            out.append((SunObservation(t, az % 360.0, el, sig, sensor=sensor), row_no))
    if not out:
        raise InputError(f"{path}: no observations (expected rows of time, az_deg, el_deg)")
    return _time_ordered(out, path, "row")


def _time_ordered(rows: list[tuple[SunObservation, int]], path: Path, unit: str) -> list[SunObservation]:
    """The observations sorted by time; a time given twice is an InputError naming both rows.

    The filter would take a repeated row as a second, independent sighting (its weight
    doubled) and two different directions at one time as a sun that jumped, so a log
    concatenated twice or merged from two sensors is refused rather than guessed at.
    """
    rows = sorted(rows, key=lambda r: (r[0].time, r[1]))
    for (a, na), (b, nb) in zip(rows, rows[1:], strict=False):
        if b.time == a.time:
            same = (a.az_deg, a.el_deg) == (b.az_deg, b.el_deg)
            raise InputError(
                f"{path}: {unit} {nb}: time {to_iso(b.time)} repeats {unit} {na}"
                + (" (the same observation twice)" if same else " with another direction")
                + "; one observation per time"
            )
    return [o for o, _ in rows]
