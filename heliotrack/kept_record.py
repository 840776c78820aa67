"""A small JSON record in ``run``'s ``--state`` folder that a restart reads back: the SCADA
commands in force (:mod:`heliotrack.stow_requests`, :mod:`heliotrack.manual_overrides`).

Written atomically when it changes; a record that cannot be read is said in one warning
line and ignored, so the commands are SCADA's to give again, and the file is rewritten at
the next change.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Any, TypeVar

from controller.atomic import atomic_write

log = logging.getLogger("heliotrack.run")

T = TypeVar("T", bound=dict)


def note_record(path: Path | None, key: str, now: T, last: T | None, what: str) -> T | None:
    """Write ``now`` as the table ``key`` of ``path`` when it differs from ``last`` (the value
    last written; None: not yet by this process); return the value now on record (``last``
    without a path: nothing is kept)."""
    if path is None:
        return last
    if now != last:
        write_record(path, key, now, what)
    return now


def write_record(path: Path, key: str, value: dict[str, Any], what: str) -> None:
    """Write ``{"time": now, key: value}`` to ``path``; a failure is one warning naming ``what``."""
    try:
        atomic_write(path, json.dumps({"time": time.time(), key: value}) + "\n")
    except OSError as exc:  # said once for this value, not every cycle
        log.warning("%s: not written (%s): %s in force would not survive a restart", path, exc, what)


def read_record(path: Path, key: str, what: str) -> dict[str, Any]:
    """The table ``key`` of the record at ``path`` (empty without a file, or with one that
    cannot be read: then one warning line naming ``what``)."""
    try:
        record = json.loads(path.read_text())
        value = record[key]
        if not isinstance(value, dict):
            raise TypeError(f"{key} is not a table")
    except FileNotFoundError:
        return {}
    except (OSError, ValueError, TypeError, KeyError) as exc:
        log.warning("%s: not read (%s); no %s taken from it", path, exc, what)
        return {}
    return value
