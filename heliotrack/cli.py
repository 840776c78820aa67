"""The ``heliotrack`` console script.

Each subcommand lives in its own module under :mod:`heliotrack.commands` and exposes
``register(subparsers)``; the module adds its parser and sets ``func`` to a callable taking
the parsed namespace and returning an exit code.  Adding a command means adding one module
and one name to :data:`COMMAND_MODULES`.  A command whose default log level is not WARNING
sets ``default_log_level`` in its parser's defaults: a level (``run``: INFO), or a function
of the parsed arguments (``simulate``: INFO with ``--realtime``).

The log options (:mod:`heliotrack.logs`) come before the command, and commands that serve
for long (``run``) accept them after it too.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from . import __version__
from .errors import USER_ERRORS, format_user_error
from .logs import add_log_options, logging_configured

#: Subcommand modules, in the order ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "run",
    "check",
    "simulate",
    "replay",
    "report",
    "hil",
    "hil_record",
    "protocol",
    "bench",
    "sunpath",
    "classify",
    "estimate",
    "calibrate",
    "config",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="heliotrack",
        description="Camera-based sun-tracker controller and its hardware-in-the-loop emulator.",
    )
    parser.add_argument("--version", action="version", version=f"heliotrack {__version__}")
    add_log_options(parser, top_level=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(f"heliotrack.commands.{name}").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    default = getattr(args, "default_log_level", "WARNING")
    level = args.log_level or (default(args) if callable(default) else default)
    try:
        with logging_configured(level, args.log_format or "text", args.log_file):
            return int(args.func(args) or 0)
    except USER_ERRORS as exc:
        print(format_user_error(exc), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away (`| head`): what was left to print is not wanted, and the files
        # are written; stdout to /dev/null so that the flush at exit does not fail again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # as a process ended by SIGPIPE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
