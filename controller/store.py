"""The controller's store: learned state and history in one SQLite file that survives power loss.

What it holds:

* ``state``: named JSON documents (the sun-path filter's learned state, calibration
  results), each with a version that grows by one on every write;
* ``observations`` and ``setpoints``: the history, rotated by age.

Durability: WAL journal with ``synchronous=FULL`` (a committed transaction survives a
power cut; an interrupted one is rolled back on the next open), one transaction per write.
The file carries a schema version (``PRAGMA user_version``) and is migrated forward on
open; a file from a newer heliotrack is refused, not rewritten.

A missing store is created.  A store that cannot be used (not a database, failed
integrity check, unknown schema) raises :class:`StoreError` with a one-line message; the
caller starts safely without it (:func:`open_store_or_none`) and the bad file is kept for
inspection, renamed, never silently replaced.
"""

from __future__ import annotations

import json
import math
import sqlite3
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import UserError

SCHEMA_VERSION = 1

#: Forward migrations: MIGRATIONS[v] takes a store at schema v - 1 to v.
MIGRATIONS: dict[int, Sequence[str]] = {
    1: (
        """CREATE TABLE state (
               name TEXT PRIMARY KEY,
               version INTEGER NOT NULL,
               updated REAL NOT NULL,
               body TEXT NOT NULL)""",
        """CREATE TABLE observations (
               time REAL NOT NULL, sensor TEXT NOT NULL,
               az_deg REAL, el_deg REAL, sigma_deg REAL, accepted INTEGER NOT NULL)""",
        "CREATE INDEX observations_time ON observations(time)",
        """CREATE TABLE setpoints (
               time REAL NOT NULL, tracker TEXT NOT NULL, mode TEXT NOT NULL,
               source TEXT NOT NULL, targets TEXT NOT NULL, actual TEXT NOT NULL,
               error TEXT NOT NULL)""",
        "CREATE INDEX setpoints_time ON setpoints(time)",
    ),
}


class StoreError(UserError):
    """The store file cannot be used; the message says which file and why."""


class StoreBusy(StoreError):
    """Another program holds the store's lock (a backup, a browser, a second instance):
    the file is sound and must not be moved aside."""


#: How long a write waits for another program's lock before it is skipped (s): the loop
#: runs the store's writes between its exchanges, and a longer wait would stall them.
BUSY_TIMEOUT_S = 0.5
#: How long opening the store waits for such a lock (s).
OPEN_TIMEOUT_S = 5.0
TABLES = ("state", "observations", "setpoints")


def _busy(exc: sqlite3.Error) -> bool:
    code = getattr(exc, "sqlite_errorcode", None)
    return code in (sqlite3.SQLITE_BUSY, sqlite3.SQLITE_LOCKED) or "locked" in str(exc)


@dataclass(frozen=True)
class StateRecord:
    name: str
    version: int
    updated: float
    body: Any


class Store:
    """One SQLite store (see the module docstring).

    Parameters
    ----------
    path : str or Path
        The database file (created with its folder when missing).
    check : bool
        Run SQLite's integrity check at open (fast for a store of a few MB).
    """

    def __init__(self, path: str | Path, *, check: bool = True):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, timeout=OPEN_TIMEOUT_S, isolation_level=None)
        except (OSError, sqlite3.Error) as exc:
            raise StoreError(f"{self.path}: cannot open the store ({exc})") from None
        try:
            self._setup(check)
            self._db.execute(f"PRAGMA busy_timeout={int(BUSY_TIMEOUT_S * 1000)}")
        except sqlite3.DatabaseError as exc:
            self._db.close()
            if _busy(exc):
                raise StoreBusy(f"{self.path}: held by another program ({exc})") from None
            raise StoreError(f"{self.path}: not a usable heliotrack store ({exc})") from None
        except StoreError:
            self._db.close()
            raise

    def _setup(self, check: bool) -> None:
        db = self._db
        mode = db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
        if str(mode).lower() != "wal":
            raise StoreError(f"{self.path}: cannot use write-ahead logging (journal {mode})")
        db.execute("PRAGMA synchronous=FULL")
        if check:
            result = db.execute("PRAGMA quick_check").fetchone()[0]
            if result != "ok":
                raise StoreError(f"{self.path}: integrity check failed ({result})")
        version = db.execute("PRAGMA user_version").fetchone()[0]
        if version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path}: store schema {version} is newer than this "
                f"heliotrack ({SCHEMA_VERSION}); upgrade heliotrack"
            )
        if version == 0 and db.execute("SELECT count(*) FROM sqlite_master WHERE type='table'").fetchone()[0]:
            raise StoreError(f"{self.path}: an SQLite file that is not a heliotrack store")
        for v in range(version + 1, SCHEMA_VERSION + 1):
            with self._transaction():
                for sql in MIGRATIONS[v]:
                    db.execute(sql)
                db.execute(f"PRAGMA user_version={v}")
        have = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        missing = [t for t in TABLES if t not in have]
        if missing:
            raise StoreError(f"{self.path}: a heliotrack store without its table(s) {', '.join(missing)}")

    def _transaction(self):
        return _Transaction(self._db)

    @property
    def schema_version(self) -> int:
        return int(self._db.execute("PRAGMA user_version").fetchone()[0])

    # -- state --------------------------------------------------------------------------
    def put_state(self, name: str, body: Any, now: float | None = None) -> int:
        """Write a JSON document under ``name``; returns its new version (1, 2, ...)."""
        text = json.dumps(body, allow_nan=False, separators=(",", ":"))
        t = time.time() if now is None else now
        with self._transaction():
            row = self._db.execute("SELECT version FROM state WHERE name=?", (name,)).fetchone()
            version = (row[0] if row else 0) + 1
            self._db.execute(
                "INSERT OR REPLACE INTO state(name, version, updated, body) VALUES (?, ?, ?, ?)",
                (name, version, t, text),
            )
        return version

    def get_state(self, name: str) -> StateRecord | None:
        """The document under ``name`` (None when never written).

        Raises
        ------
        StoreError
            The stored text is not JSON (the row is left as it is).
        """
        try:
            row = self._db.execute(
                "SELECT version, updated, body FROM state WHERE name=?", (name,)
            ).fetchone()
        except sqlite3.Error as exc:
            raise StoreError(f"{self.path}: state {name!r} cannot be read ({exc})") from None
        if row is None:
            return None
        try:
            body = json.loads(row[2])
        except (TypeError, json.JSONDecodeError, RecursionError) as exc:
            reason = "nested too deeply" if isinstance(exc, RecursionError) else exc
            raise StoreError(f"{self.path}: state {name!r} version {row[0]} is not JSON ({reason})") from None
        try:
            return StateRecord(name, int(row[0]), float(row[1]), body)
        except (TypeError, ValueError, OverflowError):
            raise StoreError(
                f"{self.path}: state {name!r}: version {row[0]!r} or time {row[1]!r} is not a number"
            ) from None

    def copy_state(self, name: str, new_name: str) -> bool:
        """Copy the row ``name`` to ``new_name`` as stored, whatever its text (kept aside
        for a look); False when there is no such row."""
        with self._transaction():
            cur = self._db.execute(
                "INSERT OR REPLACE INTO state(name, version, updated, body) "
                "SELECT ?, version, updated, body FROM state WHERE name=?",
                (new_name, name),
            )
        return cur.rowcount > 0

    # -- history --------------------------------------------------------------------------
    def add_observations(self, rows: Iterable[tuple[float, str, float, float, float, bool]]) -> None:
        """(time, sensor, az_deg, el_deg, sigma_deg, accepted) rows, in one transaction."""
        with self._transaction():
            self._db.executemany(
                "INSERT INTO observations VALUES (?, ?, ?, ?, ?, ?)",
                [(t, s, _num(a), _num(e), _num(g), int(ok)) for t, s, a, e, g, ok in rows],
            )

    def add_setpoints(
        self, rows: Iterable[tuple[float, str, str, str, Sequence[float], Sequence[float], str]]
    ) -> None:
        """(time, tracker, mode, source, targets_deg, actual_deg, error) rows."""
        with self._transaction():
            self._db.executemany(
                "INSERT INTO setpoints VALUES (?, ?, ?, ?, ?, ?, ?)",
                [
                    (t, tr, m, src, json.dumps([_num(x) for x in tg]), json.dumps([_num(x) for x in ac]), err)
                    for t, tr, m, src, tg, ac, err in rows
                ],
            )

    def history(self, table: str, since: float = -math.inf) -> list[tuple]:
        if table not in ("observations", "setpoints"):
            raise ValueError(table)
        return self._db.execute(f"SELECT * FROM {table} WHERE time >= ? ORDER BY time", (since,)).fetchall()

    def rotate(self, max_age_s: float, now: float | None = None) -> int:
        """Delete history older than ``max_age_s``; returns the rows removed."""
        cutoff = (time.time() if now is None else now) - max_age_s
        with self._transaction():
            n = self._db.execute("DELETE FROM observations WHERE time < ?", (cutoff,)).rowcount
            n += self._db.execute("DELETE FROM setpoints WHERE time < ?", (cutoff,)).rowcount
        return n

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on an exception)."""

    def __init__(self, db: sqlite3.Connection):
        self.db = db

    def __enter__(self) -> None:
        self.db.execute("BEGIN IMMEDIATE")

    def __exit__(self, exc_type, exc, tb) -> None:
        self.db.execute("ROLLBACK" if exc_type else "COMMIT")


def _num(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def open_store_or_none(path: str | Path, warn: Callable[[str], None]) -> Store | None:
    """Open the store, or report why not and return None (the caller starts without it).

    A file that is not a usable store is renamed ``<name>.unusable-<UTC time>`` (kept for
    inspection, never deleted) and a new store is created in its place; if even that fails,
    None.  ``warn`` gets one line per problem.
    """
    path = Path(path)
    try:
        if path.is_file() and path.stat().st_size == 0:  # nothing was ever committed to it
            warn(f"{path}: an empty file; the store starts afresh in it")
    except OSError:
        pass  # Store() below says what is wrong with the path
    try:
        return Store(path)
    except StoreBusy as exc:  # sound, only locked: left where it is for the next start
        warn(f"{exc}; running without the store this time (it is not moved)")
        return None
    except StoreError as exc:
        if not path.exists() or "newer than this heliotrack" in str(exc):
            # a newer store is left as it is: the old program must not touch it
            warn(f"{exc}; running without a store")
            return None
        warn(str(exc))
    aside = path.with_name(f"{path.name}.unusable-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}")
    try:
        path.rename(aside)
        for suffix in ("-wal", "-shm"):
            side = path.with_name(path.name + suffix)
            if side.exists():
                side.rename(aside.with_name(aside.name + suffix))
        warn(f"{path}: kept the unusable store as {aside.name}; starting a new one")
        return Store(path)
    except (OSError, StoreError) as exc:
        warn(f"{path}: running without a store ({exc})")
        return None
