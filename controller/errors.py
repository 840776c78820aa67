"""Exceptions for user mistakes (bad config, bad input files); the CLI prints them plainly."""

from __future__ import annotations

from pathlib import Path


class UserError(Exception):
    """Base class for errors caused by the user's input, not by a bug."""


class ConfigError(UserError):
    """A configuration file is missing, unreadable or invalid.

    The message names the file, the key path (``trackers[1].drive.device_id``) and what
    was expected, so the user can fix it without reading code.
    """

    def __init__(
        self,
        file: str | Path | None,
        key: str,
        expected: str,
        got: object = None,
        notes: tuple[str, ...] = (),
    ):
        self.file = str(file) if file is not None else "<config>"
        self.key = key
        self.expected = expected
        self.got = got
        # no file: a command-line option (``--state``), named alone
        where = (f"{self.file}: {key}" if file is not None else key) if key else self.file
        detail = f"expected {expected}"
        if got is not None:
            detail += f", got {got!r}"
        if notes:  # which item an index means: "(trackers[1] is 'row-1')"
            detail += f" ({'; '.join(notes)})"
        super().__init__(f"{where}: {detail}")


class InputError(UserError):
    """A data file (observations, images, station data) cannot be used; says which and why."""
