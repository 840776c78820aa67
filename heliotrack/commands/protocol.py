"""``heliotrack protocol export DIR``: write every generated firmware_protocol artefact;
``heliotrack protocol conformance``: check a real drive against the protocol's rules
(:mod:`controller.drives.modbus.conformance`, :mod:`controller.drives.canopen.conformance`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("protocol", help="the drive wire contract")
    ps = p.add_subparsers(dest="protocol_command", metavar="WHAT")
    ps.required = True
    e = ps.add_parser("export", help="write the register reference, the C header and the CANopen EDS")
    e.add_argument("dir", type=Path)
    e.set_defaults(func=run_export)
    c = ps.add_parser(
        "conformance",
        help="check a drive (Modbus or CANopen) against the protocol's rules (firmware bring-up)",
        description="Connect to one tracker's drive of a plant file and check it against the rules "
        "of the protocol (firmware_protocol/generated/REGISTERS.md 'Behaviour', docs/canopen.md): one row per "
        "rule, pass, FAIL, warn or skip.  Without --may-move nothing moves: only values the drive "
        "holds are written, or values it must refuse.  Exit 0 when nothing failed.",
    )
    c.add_argument("--config", type=Path, required=True, help="plant TOML")
    c.add_argument("--tracker", required=True, help="the tracker whose drive to check")
    c.add_argument(
        "--may-move",
        action="store_true",
        help="also the checks that move axis 0 by a few degrees and stow the drive (watchdog, "
        "STOW/RESUME, clamping): only with the tracker clear to move",
    )
    c.add_argument("--watchdog-s", type=float, default=2.0, help="the watchdog timeout its check sets (s)")
    c.set_defaults(func=run_conformance)


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


def run_conformance(args: argparse.Namespace) -> int:
    import asyncio

    from controller.drives.base import DriveCommError
    from controller.drives.conformance import FAIL
    from controller.drives.registry import open_drive
    from controller.errors import InputError
    from heliotrack.runtime import load_plant

    config = load_plant(args.config, "protocol conformance")
    tracker = next((t for t in config.trackers if t.name == args.tracker), None)
    if tracker is None:
        names = ", ".join(t.name for t in config.trackers)
        raise InputError(f"--tracker {args.tracker!r}: not in {args.config} (its trackers: {names})")
    if not 0.5 <= args.watchdog_s <= 60:
        raise InputError(f"--watchdog-s {args.watchdog_s:g}: expected 0.5 to 60 s")
    link = config.links_by_name[tracker.link]
    if link.kind == "canopen":
        from controller.drives.canopen.conformance import run_checks
    elif link.kind in ("modbus-rtu", "modbus-tcp"):
        from controller.drives.modbus.conformance import run_checks  # type: ignore[assignment]
    else:
        raise InputError(
            f"--tracker {args.tracker}: its link {tracker.link!r} is {link.kind}: no conformance checks for it"
        )

    async def main() -> int:
        drive = open_drive(link, tracker.device_id)  # a Modbus client wants the running loop
        failed = n = 0
        async for check in run_checks(drive, may_move=args.may_move, watchdog_s=args.watchdog_s):  # type: ignore[arg-type]
            n += 1
            failed += check.outcome == FAIL
            print(f"{check.outcome:<5} {check.name}: {check.detail}", flush=True)
        print(f"{n - failed} of {n} check(s) without a failure" + (f"; {failed} FAILED" if failed else ""))
        return 1 if failed else 0

    try:
        return asyncio.run(main())
    except DriveCommError as exc:
        print(f"stopped: {exc}")
        return 1
