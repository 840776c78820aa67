"""Atomic persistence of the sun-path filter's learned state (JSON).

Saving goes through :func:`controller.atomic.atomic_write` (temporary file, fsync, rename,
fsync of the folder), so a crash leaves either the old or the new state.  Loading checks
the content (:func:`.persistence.kalman_from_dict`): a state that is not physical or not
plausible is refused like a corrupt one, with one line naming the file and the field.  A
state file that cannot be used is never overwritten silently: :func:`save_state` refuses
to replace it unless told to.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..atomic import atomic_write
from ..errors import InputError
from ..store import Store, StoreError
from .kalman import SunPathKalman
from .persistence import SnapshotError, kalman_from_dict

FORMAT = "heliotrack.sunpath.state"
VERSION = 1
#: The entry of the learned state in a :class:`~controller.store.Store`.
STORE_KEY = "sunpath"


class StateError(InputError):
    """A state file exists but cannot be used; the message says which file and why.

    Attributes
    ----------
    reason : str
        ``"unreadable"`` (the file system refused), ``"corrupt"`` (not JSON, or not a
        sun-path state), ``"version"`` (another version of the format) or ``"invalid"``
        (a state that reads but is not physical or not plausible).
    """

    def __init__(self, message: str, reason: str = "corrupt"):
        super().__init__(message)
        self.reason = reason


def _read(path: Path) -> dict:
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise StateError(
            f"{path}: cannot read sun-path state ({why})",
            "unreadable" if isinstance(exc, OSError) else "corrupt",
        ) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StateError(
            f"{path}: corrupt sun-path state: not JSON (line {exc.lineno}, "
            f"column {exc.colno}: {exc.msg}); fix or remove the file"
        ) from None
    except RecursionError:
        raise StateError(f"{path}: corrupt sun-path state: JSON nested too deeply") from None
    return doc


def learned_site(kf: SunPathKalman) -> tuple[float, float] | None:
    """(latitude, longitude), deg, of the site a filter tracks: what it learned once started,
    else the site it was given; None when neither."""
    from .kalman_config import LAT, LON

    if kf.initialised:
        return float(kf.x[LAT]), float(kf.x[LON])
    if kf.site is not None:
        return kf.site.latitude, kf.site.longitude
    return None


def load_from_store(store: Store, now: float | None = None) -> SunPathKalman | None:
    """The filter saved in ``store`` (None when never saved); StateError when it cannot be
    used (the entry is left as it is)."""
    where = f"{store.path}: state {STORE_KEY!r}"
    try:
        rec = store.get_state(STORE_KEY)
    except StoreError as exc:
        raise StateError(str(exc)) from None
    return None if rec is None else filter_from_doc(rec.body, where, now)


def save_to_store(store: Store, kf: SunPathKalman) -> int:
    """Save ``kf`` in ``store`` (one transaction); returns the entry's new version."""
    return store.put_state(STORE_KEY, state_doc(kf, f"{store.path}: state {STORE_KEY!r}"))


def load_state(path: str | Path, now: float | None = None) -> SunPathKalman | None:
    """Load a filter from ``path``; None when the file does not exist.

    Parameters
    ----------
    path : str or Path
    now : float, optional
        The present (POSIX s, the caller's clock): a state saved more than a day after it
        is refused.  None: the time is only checked against 2000-01-01.

    Raises
    ------
    StateError
        The file exists but cannot be used; the one-line message names the file, and for
        a state that reads but is refused, the field (``filter.x[lat_deg]``) and why.
    """
    path = Path(path)
    if not path.exists():
        return None
    return filter_from_doc(_read(path), str(path), now)


def filter_from_doc(doc: dict, where: str, now: float | None = None) -> SunPathKalman:
    """The filter of a state document (a file's JSON, or the store's ``sunpath`` entry),
    validated; ``where`` starts every message (StateError)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise StateError(f"{where}: not a sun-path state (expected format {FORMAT!r})")
    if doc.get("version") != VERSION:
        raise StateError(
            f"{where}: sun-path state version {doc.get('version')!r}, expected {VERSION}", "version"
        )
    if not isinstance(doc.get("filter"), dict):
        raise StateError(f"{where}: corrupt sun-path state: field 'filter' is missing; fix or remove it")
    try:
        return kalman_from_dict(doc["filter"], SunPathKalman, now=now)
    except SnapshotError as exc:
        raise StateError(
            f"{where}: invalid sun-path state: field 'filter.{exc.field}': {exc.why}; fix or remove it",
            "invalid",
        ) from None
    except (KeyError, TypeError, ValueError) as exc:
        raise StateError(
            f"{where}: corrupt sun-path state: field 'filter' is invalid ({exc}); fix or remove it",
            "invalid",
        ) from None


def state_doc(kf: SunPathKalman, where: str) -> dict:
    """The state document of ``kf``, checked to load again (StateError otherwise)."""
    snapshot = kf.to_dict()
    try:  # what is written must load again: never replace a state with a broken one
        kalman_from_dict(snapshot, SunPathKalman)
    except SnapshotError as exc:
        raise StateError(
            f"{where}: not saving an invalid sun-path state (field 'filter.{exc.field}': {exc.why})",
            "invalid",
        ) from None
    return {"format": FORMAT, "version": VERSION, "filter": snapshot}


def save_state(path: str | Path, kf: SunPathKalman, overwrite_corrupt: bool = False) -> None:
    """Atomically write ``kf`` to ``path``.

    An existing file that is not a usable state (unreadable, corrupt, another version, or
    refused by the checks of :func:`load_state`) is kept (StateError) unless
    ``overwrite_corrupt``: it may hold something the user wants.

    Raises
    ------
    StateError
        The existing file cannot be used and ``overwrite_corrupt`` is false, or ``kf``
        itself would not load again (the file is then left as it was).
    OSError
        The file cannot be written; the old one is untouched.
    """
    path = Path(path)
    if path.exists() and not overwrite_corrupt:
        load_state(path)  # raises StateError on a file that is not a usable state
    doc = state_doc(kf, str(path))
    atomic_write(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")
