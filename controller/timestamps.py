"""Timestamps in text: the one place that says which forms are accepted.

Frame file names, ``--time``, ``--start`` and the time column of CSV files all go through
:func:`parse_timestamp` (a whole string) or :func:`time_from_name` (a timestamp somewhere
in a file name).  The accepted forms:

=================  =======================================  ===============================
form               examples                                 notes
=================  =======================================  ===============================
canonical          ``2026-03-20T10-15-00Z``,                what heliotrack writes (frame
                   ``2026-03-20T10-15-00.250Z``             names): file-name safe, UTC
ISO 8601 extended  ``2026-03-20T10:15:00Z``,                ``T`` or a space between date
                   ``2026-03-20 10:15:00.5+03:30``          and time
ISO 8601 basic     ``20260320T101500Z``,                    ``T`` or ``_`` between date and
                   ``20260320_101500.25+0330``              time
camera style       ``2026-03-20_10-15-00``,                 what many cameras and NVRs
                   ``2026-03-20-10-15-00``                  write
=================  =======================================  ===============================

The zone is ``Z``, ``+HH:MM``, ``-HH:MM``, ``+HHMM``, ``-HHMM`` or, file-name safe,
``+HH-MM`` and ``-HH-MM`` (dropped before, a name such as ``2024-03-20T08-00-00+03-30``
was read 3.5 h late); without one the time is
UTC (callers that must not guess, such as observation CSVs, pass ``require_zone=True``).
The time of day uses one separator throughout (``10-15-00`` or ``10:15:00`` or
``101500``); ISO 8601 forms may leave out the seconds (``10:15``, ``1015``); a fraction of
a second may follow the seconds after ``.`` or ``,``.
"""

from __future__ import annotations

import math
import re
from datetime import UTC, datetime, timedelta

from .errors import InputError

__all__ = [
    "CANONICAL_EXAMPLE",
    "format_name_time",
    "names_without_zone",
    "parse_timestamp",
    "time_from_name",
    "to_iso",
    "zone_warning",
]

#: An example of the canonical form, for messages and docs.
CANONICAL_EXAMPLE = "2026-03-20T10-15-00Z"

_TIMESTAMP = re.compile(
    r"(?<!\d)(?P<y>\d{4})(?P<ds>-?)(?P<mo>\d{2})(?P=ds)(?P<d>\d{2})"
    r"(?P<sep>[Tt _-])"
    r"(?P<h>\d{2})(?P<ts>[:-]?)(?P<mi>\d{2})"
    r"(?:(?P=ts)(?P<s>\d{2})(?:[.,](?P<frac>\d{1,9}))?)?"
    r"(?P<tz>[Zz]|[+-]\d{2}[:-]?\d{2})?(?!\d)(?![:-]\d)"
)


#: The years a time may name: wider than any tracker's life, narrower than pandas' (1677-2262)
#: and pvlib SPA's, so a typo (2924 for 2024) is an error, not a crash or a run of centuries.
YEARS = (1900, 2200)


def _from_match(m: re.Match[str]) -> float | None:
    g = m.groupdict()
    if not YEARS[0] <= int(g["y"]) <= YEARS[1]:
        return None
    # ISO basic dates run their fields together; a '-' or ':' time separator belongs to the
    # extended or camera forms, which have separated dates as well.
    if not g["ds"] and (g["ts"] or (g["tz"] and len(g["tz"]) > 5)):
        return None  # a basic date has a basic time and zone: "20240101_2024-03-20..." is two things
    # Seconds may be left out in ISO 8601 (10:15, 1015), not in the hyphenated forms.
    if g["s"] is None and g["ts"] == "-":
        return None
    try:
        dt = datetime(
            int(g["y"]),
            int(g["mo"]),
            int(g["d"]),
            int(g["h"]),
            int(g["mi"]),
            int(g["s"] or 0),
            tzinfo=UTC,
        )
    except ValueError:
        return None
    t = dt.timestamp()
    if g["frac"]:
        t += float("0." + g["frac"])
    tz = g["tz"]
    if tz and tz not in ("Z", "z"):
        hh, mm = int(tz[1:3]), int(tz[-2:])
        if hh > 23 or mm > 59:
            return None
        t -= (1 if tz[0] == "+" else -1) * (hh * 3600 + mm * 60)
    return t


def time_from_name(name: str) -> float | None:
    """POSIX seconds (UTC) from the first timestamp in a file name, or None.

    Only the last path component is searched, so a dated folder does not date its files.

    Examples
    --------
    >>> time_from_name("frames/2026-03-20T10-15-00Z.png")
    1774001700.0
    >>> time_from_name("cam1_2026-03-20_10-15-00.jpg") == time_from_name("2026-03-20T10:15:00Z")
    True
    >>> time_from_name("IMG_0001.png") is None
    True
    """
    found = _stamp_in_name(name)
    return None if found is None else found[0]


def _stamp_in_name(name: str) -> tuple[float, bool] | None:
    """(POSIX s, whether the stamp names its zone) of the first timestamp in a file name."""
    base = re.split(r"[\\/]", name)[-1]
    pos = 0
    while (m := _TIMESTAMP.search(base, pos)) is not None:
        t = _from_match(m)
        if t is not None:
            return t, bool(m.group("tz"))
        pos = m.start() + 1  # not past the refused match: a timestamp may start inside it
    return None


def names_without_zone(names) -> list[str]:
    """The names whose timestamp carries no zone (read as UTC by :func:`time_from_name`):
    a camera that writes local time without its offset puts the sun hours off."""
    out = []
    for n in names:
        found = _stamp_in_name(str(n))
        if found is not None and not found[1]:
            out.append(str(n))
    return out


def zone_warning(naive: list[str], total: int) -> str:
    """One line for :func:`names_without_zone`'s finding ("" when there is none)."""
    if not naive:
        return ""
    name = re.split(r"[\\/]", naive[0])[-1]
    return (
        f"{len(naive)} of {total} frame names carry no zone ({name}{', ...' if len(naive) > 1 else ''}): "
        f"read as UTC; if they are local times, name them with their offset (e.g. +03-30) or in UTC "
        f"with Z, as in {CANONICAL_EXAMPLE}.png"
    )


def parse_timestamp(text: str, where: str = "time", *, require_zone: bool = False) -> float:
    """POSIX seconds (UTC) from a whole string in one of the accepted forms.

    Parameters
    ----------
    text : str
        The timestamp, nothing else around it (surrounding blanks are ignored).
    where : str
        Prefix of the error message: the option, or ``file:line: column``.
    require_zone : bool
        Refuse a time without a zone instead of taking it as UTC.

    Raises
    ------
    InputError
        The text is not one of the forms, names an impossible date, or lacks a zone when
        one is required.
    """
    s = str(text).strip()
    m = _TIMESTAMP.fullmatch(s)
    t = _from_match(m) if m else None
    if t is None:
        if m and not YEARS[0] <= int(m.group("y")) <= YEARS[1]:
            raise InputError(f"{where}: year {m.group('y')} is outside {YEARS[0]}-{YEARS[1]}, got {text!r}")
        raise InputError(
            f"{where}: expected a time such as {CANONICAL_EXAMPLE} or 2026-03-20T10:15:00+03:30, got {text!r}"
        )
    if require_zone and m is not None and not m.group("tz"):
        raise InputError(f"{where}: time {text!r} has no zone; add one (Z or e.g. +03:30)")
    return t


def format_name_time(t: float, *, millis: bool | None = None) -> str:
    """The canonical file-name form of POSIX time ``t`` (UTC).

    ``millis``: add ``.fff`` (default: only when ``t`` has a fraction of a second).

    >>> format_name_time(1774001700.0)
    '2026-03-20T10-15-00Z'
    >>> format_name_time(1774001700.25)
    '2026-03-20T10-15-00.250Z'
    """
    if not math.isfinite(t):
        raise ValueError(f"not a time: {t!r}")
    whole = math.floor(t)
    ms = int(round((t - whole) * 1000))
    if ms == 1000:
        whole, ms = whole + 1, 0
    dt = datetime(1970, 1, 1, tzinfo=UTC) + timedelta(seconds=whole)
    if millis is None:
        millis = ms != 0
    frac = f".{ms:03d}" if millis else ""
    return dt.strftime("%Y-%m-%dT%H-%M-%S") + frac + "Z"


def to_iso(t: float) -> str:
    """ISO 8601 UTC text of POSIX time ``t`` with a ``Z`` (for JSON and CSV output)."""
    return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")
