"""``heliotrack hil drive``: a standalone emulated drive for any Modbus or CANopen master."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("hil", help="run a piece of the emulated world on its own")
    hs = p.add_subparsers(dest="hil_command", metavar="WHAT")
    hs.required = True
    _register_drive(hs)
    # further ``hil`` subcommands register here, one line each (their own modules)


def _register_drive(hs: argparse._SubParsersAction) -> None:
    d = hs.add_parser(
        "drive",
        help="serve an emulated drive firmware in real time",
        description="Serve an emulated slewing drive on a pty (Modbus RTU) or "
        "on 127.0.0.1 (Modbus TCP), or as CANopen CiA 402 nodes (one "
        "per axis: --id, --id + 1) behind an emulated slcan USB-CAN "
        "adapter on a pty (--protocol canopen; open it with python-can "
        "interface 'slcan'). With --link pty the first stdout "
        "line is 'PTY <path>'; with --link tcp it is 'TCP <host>:<port>'. "
        "Runs until SIGINT or SIGTERM; then the last line on stderr gives each axis's "
        "angle and mode.  The firmware counts its own (monotonic) time: a step of the "
        "wall clock neither fires nor delays its watchdog.",
    )
    d.add_argument("--link", choices=("pty", "tcp"), default="pty")
    d.add_argument("--protocol", choices=("modbus", "canopen"), default="modbus")
    d.add_argument("--axes", type=int, choices=(1, 2), default=2)
    d.add_argument(
        "--id", type=int, default=1, help="Modbus slave id (1-247), or CANopen node id of axis 0 (1-126)"
    )
    d.add_argument("--port", type=int, default=0, help="TCP port (0: any free port)")
    d.add_argument(
        "--heartbeat-timeout",
        type=float,
        default=10.0,
        help="watchdog timeout in s (0 disables); masters may rewrite it",
    )
    d.add_argument("--max-speed", type=float, default=1.0, help="deg/s")
    d.add_argument(
        "--stow",
        type=float,
        nargs="*",
        default=None,
        help="stow angle per axis, deg (default 180 90 for two axes, 0 for one)",
    )
    d.set_defaults(func=run_drive)


def run_drive(args: argparse.Namespace) -> int:
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink

    fw = firmware(args)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    if args.protocol == "canopen":
        return _serve_canopen(args, fw, stop)
    pty = None
    try:
        if args.link == "pty":
            pty = PtyLink.open()
            server = ModbusServerThread({args.id: fw}, serial_url=pty.url).start()
            print(f"PTY {pty.path}", flush=True)
        else:
            server = ModbusServerThread({args.id: fw}, tcp=("127.0.0.1", args.port)).start()
            print(f"TCP 127.0.0.1:{server.tcp_port}", flush=True)
        print(
            f"drive id {args.id}, {args.axes} axis(es), heartbeat timeout {args.heartbeat_timeout:g} s",
            file=sys.stderr,
            flush=True,
        )
        while not stop.wait(0.1):
            fw.update()  # the watchdog runs even when nobody polls
        server.stop()
    finally:
        if pty:
            pty.close()
    _report(fw)
    return 0


def firmware(args: argparse.Namespace):
    """The emulated firmware the options describe (a one-line error for a bad option)."""
    from hil.drive import AxisParams, DriveFirmware
    from hil.errors import HilError

    if args.protocol == "canopen":
        if args.link != "pty":
            raise HilError(
                "--protocol canopen serves an slcan adapter on a pty: use --link pty (CAN has no TCP link)"
            )
    elif not 1 <= args.id <= 247:
        raise HilError(f"--id must be 1..247, got {args.id}")
    if not args.heartbeat_timeout >= 0:  # NaN too
        raise HilError(
            f"--heartbeat-timeout must be >= 0 s (0 disables the watchdog), got {args.heartbeat_timeout}"
        )
    if not args.max_speed > 0:
        raise HilError(f"--max-speed must be > 0 deg/s, got {args.max_speed}")
    from firmware_protocol import ProtocolError, encode, register

    for option, name, value in (
        ("--heartbeat-timeout", "HEARTBEAT_TIMEOUT", args.heartbeat_timeout),
        ("--max-speed", "MAX_SPEED", args.max_speed),
    ):
        try:  # the firmware's own register must hold it, or every read of it fails
            encode(register(name), value)
        except ProtocolError as exc:
            raise HilError(f"{option}: {exc}") from None
    stow = args.stow if args.stow else ([180.0, 90.0] if args.axes == 2 else [0.0])
    if len(stow) != args.axes:
        raise HilError(f"--stow needs {args.axes} value(s), got {len(stow)}")
    if args.axes == 2:
        limits = [(0.0, 360.0), (0.0, 90.0)]
    else:
        limits = [(-60.0, 60.0)]
    axes = [
        AxisParams(
            max_speed=args.max_speed,
            soft_min=lo,
            soft_max=hi,
            hard_min=lo - 5,
            hard_max=hi + 5,
            stow_angle=s,
            initial_angle=s,
        )
        for (lo, hi), s in zip(limits, stow)
    ]
    for k, (s, (lo, hi)) in enumerate(zip(stow, limits)):
        if not lo <= s <= hi:
            raise HilError(f"--stow: axis {k} stow angle {s:g} outside its travel [{lo:g}, {hi:g}] deg")
    # wall time for nothing but its reports; physics, watchdog and uptime on its own ticks
    return DriveFirmware(axes, time.time, heartbeat_timeout=args.heartbeat_timeout, monotonic=time.monotonic)


def _report(fw) -> None:
    """The last line on stderr: each axis's angle and mode as the firmware left them."""
    from firmware_protocol import register

    fw.update()
    axes = "; ".join(
        f"axis {k} {fw.value(register('ACTUAL_ANGLE'), k):.2f} deg {fw.modes[k].name}"
        + (" COMM_LOST" if fw.comm_lost else "")
        for k in range(len(fw.axes))
    )
    print(f"drive stopped: {axes}", file=sys.stderr, flush=True)


def _serve_canopen(args: argparse.Namespace, fw, stop: threading.Event) -> int:
    """CANopen nodes on a private virtual bus, reachable through an slcan pty."""
    import os

    from firmware_protocol.canopen import check_node_id
    from hil.canopen import CanopenNetworkEmulator, open_slcan_pty
    from hil.errors import HilError

    try:
        check_node_id(args.id, args.axes)
    except ValueError as exc:
        raise HilError(f"--id: {exc}") from None
    channel = f"heliotrack-hil-{os.getpid()}"  # private to this process
    emulator = CanopenNetworkEmulator(channel).start()
    link, adapter = None, None
    try:
        emulator.add_drive(fw, args.id)
        link, adapter = open_slcan_pty(channel)
        print(f"PTY {link.path}", flush=True)
        nodes = ", ".join(str(args.id + k) for k in range(args.axes))
        print(
            f"CANopen node(s) {nodes} (CiA 402 profile position), slcan adapter; "
            f"heartbeat timeout {args.heartbeat_timeout:g} s",
            file=sys.stderr,
            flush=True,
        )
        while not stop.wait(0.1):
            fw.update()  # the watchdog runs even when nobody talks
        _report(fw)
    finally:
        if adapter:
            adapter.stop()
            adapter.bus.shutdown()
        emulator.stop()
        if link:
            link.close()
    return 0
