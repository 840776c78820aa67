"""Logging for every command: ``--log-level``, ``--log-file``, ``--log-format text|json``.

The standard :mod:`logging` module throughout.  One handler on the root logger (stderr,
or the file), so a library's records reach the same place; our own loggers (``heliotrack.*``,
and the ``controller`` and ``hil`` packages' module loggers) log at the level asked for,
every other logger (pymodbus, python-can, canopen) at WARNING and above, whatever the
level: nothing is silenced, and a debug run is not drowned in a library's frames.  One
exception: pymodbus's ERROR for each timed-out request (with the frame dumped) counts as
DEBUG, since the link retries it and reports the failure with the drive's name, and so
does its ERROR for each request to a unit id the SunSpec server does not answer (the
client gets exception 0x0B; a client could otherwise fill the log); and so does
canopen's ERROR for the abort it sends after an SDO timeout (the drive's error says it),
pymodbus's ERROR for a reply from another unit id or transaction that it skips (frames
dumped; the link retries), its "Repeating....", and the traceback asyncio logs when
pymodbus cannot decode a Modbus TCP header (the connection closes; the link reconnects).

``json`` writes one object per line: ``time`` (ISO 8601 UTC), ``level``, ``logger``,
``message``, and the fields a caller passed as ``extra={"fields": {...}}``.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
FORMATS = ("text", "json")
#: Logger name prefixes that are ours: they log at the chosen level.
OURS = ("heliotrack", "controller", "hil", "firmware_protocol", "benchmarks")
#: Every other logger's records pass from this level.
LIBRARY_LEVEL = logging.WARNING


def add_log_options(parser: argparse.ArgumentParser, *, top_level: bool) -> None:
    """The log options; after a subcommand they default to "not given" so that the
    top-level ones stand unless repeated there."""
    default = None if top_level else argparse.SUPPRESS
    g = parser.add_argument_group("logging")
    g.add_argument(
        "--log-level",
        type=str.upper,
        choices=LEVELS,
        default=default,
        metavar="LEVEL",
        help="DEBUG, INFO, WARNING or ERROR (default: INFO for run and simulate --realtime, else WARNING)",
    )
    g.add_argument(
        "--log-file", type=Path, default=default, metavar="FILE", help="append the log here (default stderr)"
    )
    g.add_argument(
        "--log-format", choices=FORMATS, default=default, help="text lines, or one JSON object per line"
    )


def is_ours(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in OURS)


class _LevelFilter(logging.Filter):
    """Our loggers from ``level``, the libraries' from WARNING."""

    def __init__(self, level: int):
        super().__init__()
        self.level = level

    def filter(self, record: logging.LogRecord) -> bool:
        if is_ours(record.name):
            return record.levelno >= self.level
        if record.name.startswith("pymodbus") and str(record.msg).startswith(_PYMODBUS_ROUTINE):
            # (also a reply from another id or transaction, which pymodbus skips with the
            # frames dumped: a late reply on a shared line, which our links retry; and its
            # "Repeating....", which stands for a record already let through or not)
            # an ERROR, with the frame dumped, for every timed-out request, which our links
            # retry and report with the drive's name; or for every request a SCADA client
            # sends to another unit id, which it is answered (exception 0x0B): a debug
            # record, not one line per request in the plant's log
            return self.level <= logging.DEBUG
        if record.name == "asyncio" and _pymodbus_frame_error(record):
            # pymodbus raising in its protocol callback for a frame it cannot decode (a
            # damaged Modbus TCP header): asyncio logs a traceback and closes the
            # connection; the link reconnects and reports the failed exchange itself
            return self.level <= logging.DEBUG
        if record.name.startswith("canopen.sdo") and record.getMessage() in _CANOPEN_ROUTINE:
            # the same for an SDO timeout (canopen aborts the transfer and says so at ERROR,
            # in the middle of check's table); other abort codes stay errors
            return self.level <= logging.DEBUG
        return record.levelno >= max(self.level, LIBRARY_LEVEL)


#: How pymodbus begins its messages for a request that timed out (a drive link), and for
#: one to a unit id the server does not answer (the SunSpec server).
_PYMODBUS_ROUTINE = (
    "No response received",
    "requested device id does not exist",
    "ERROR: request ask for ",
    "Repeating....",
)


def _pymodbus_frame_error(record: logging.LogRecord) -> bool:
    exc = record.exc_info[1] if record.exc_info else None
    return (
        str(record.msg).startswith("Fatal error: protocol.data_received() call failed")
        and exc is not None
        and type(exc).__module__.startswith("pymodbus")
    )


#: canopen's messages for an SDO request that timed out: the abort it sends (SDO abort code
#: 0x05040000, "SDO protocol timed out") and, with retries, each retry.
_CANOPEN_ROUTINE = ("Transfer aborted by client with code 0x05040000", "No SDO response received")


def _plain(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set)):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return str(value)


class JsonFormatter(logging.Formatter):
    """One JSON object per record."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname,
            "logger": record.name,
            "message": record.getMessage(),
        }
        fields = getattr(record, "fields", None)
        if isinstance(fields, dict):
            out.update({k: _plain(v) for k, v in fields.items() if k not in out})
        if record.exc_info:
            out["exception"] = self.formatException(record.exc_info)
        return json.dumps(out, separators=(",", ":"))


TEXT_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def make_handler(fmt: str = "text", file: Path | None = None) -> logging.Handler:
    """A stream handler (stderr) or a file handler (appending), with the chosen format."""
    handler: logging.Handler
    if file is not None:
        handler = logging.FileHandler(file, encoding="utf-8")
    else:
        handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(JsonFormatter() if fmt == "json" else logging.Formatter(TEXT_FORMAT))
    return handler


@contextmanager
def logging_configured(level: str = "WARNING", fmt: str = "text", file: Path | None = None) -> Iterator[None]:
    """Log to stderr (or ``file``) for the duration of a command, then put the root
    logger back as it was (commands run in-process too, from tests)."""
    from controller.errors import ConfigError

    try:
        handler = make_handler(fmt, file)
    except OSError as exc:
        raise ConfigError(
            None, "--log-file", f"a file that can be written ({exc.strerror})", str(file)
        ) from None
    numeric = logging.getLevelName(level)
    handler.addFilter(_LevelFilter(numeric))
    root = logging.getLogger()
    before = root.level
    root.addHandler(handler)
    root.setLevel(min(numeric, LIBRARY_LEVEL))
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(before)
        handler.close()
