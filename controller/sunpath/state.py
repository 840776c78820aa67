"""Atomic persistence of the sun-path filter's learned state (JSON).

Saving writes a temporary file in the same folder, flushes it to disk and renames it over
the old one (``os.replace``), so a crash leaves either the old or the new state.  A state
file that cannot be read is reported with its path and is never overwritten silently:
:func:`save_state` refuses to replace it unless told to.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import InputError
from .kalman import SunPathKalman

FORMAT = "heliotrack.sunpath.state"
VERSION = 1


class StateError(InputError):
    """A state file exists but is corrupt, of another format or of another version."""


def _read(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise StateError(f"{path}: cannot read sun-path state ({exc.strerror})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StateError(f"{path}: corrupt sun-path state: not JSON (line {exc.lineno}, "
                         f"column {exc.colno}: {exc.msg}); fix or remove the file") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise StateError(f"{path}: not a sun-path state file (expected format {FORMAT!r})")
    if doc.get("version") != VERSION:
        raise StateError(f"{path}: sun-path state version {doc.get('version')!r}, "
                         f"expected {VERSION}")
    return doc


def load_state(path: str | Path) -> SunPathKalman | None:
    """Load a filter from ``path``; None when the file does not exist.

    Raises
    ------
    StateError
        The file exists but cannot be used; the message says why.
    """
    path = Path(path)
    if not path.exists():
        return None
    doc = _read(path)
    try:
        return SunPathKalman.from_dict(doc["filter"])
    except (KeyError, TypeError, ValueError) as exc:
        raise StateError(f"{path}: corrupt sun-path state: field 'filter' is invalid "
                         f"({exc}); fix or remove the file") from None


def save_state(path: str | Path, kf: SunPathKalman, overwrite_corrupt: bool = False) -> None:
    """Atomically write ``kf`` to ``path``.

    An existing file that is not a readable state is kept (StateError) unless
    ``overwrite_corrupt``: it may hold something the user wants.
    """
    path = Path(path)
    if path.exists() and not overwrite_corrupt:
        load_state(path)  # raises StateError on a corrupt file
    doc = {"format": FORMAT, "version": VERSION, "filter": kf.to_dict()}
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=1)
            fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
