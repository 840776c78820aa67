"""``heliotrack protocol export DIR``: write every generated firmware_protocol artefact."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("protocol", help="the drive wire contract")
    ps = p.add_subparsers(dest="protocol_command", metavar="WHAT")
    ps.required = True
    e = ps.add_parser("export", help="write the register reference and the C header")
    e.add_argument("dir", type=Path)
    e.set_defaults(func=run_export)


def run_export(args: argparse.Namespace) -> int:
    from controller.errors import InputError
    from firmware_protocol.generate import write_all

    try:
        written = write_all(args.dir)
    except OSError as exc:  # a file where the folder goes, a folder where a file goes
        raise InputError(f"{exc.filename or args.dir}: cannot write ({exc.strerror or exc})") from None
    for path in written:
        print(path)
    return 0
