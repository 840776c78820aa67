"""``heliotrack hil drive``: a standalone emulated drive for any Modbus or CANopen master."""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from heliotrack.panel_camera_writer import PanelCameraWriter


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
        "wall clock neither fires nor delays its watchdog.  With --panel-camera DIR a "
        "fisheye camera rides on the panel the drive turns (its pose: the true output "
        "angles plus --mount-offset) and writes what it sees, on whole seconds of the wall "
        "clock, as DIR/YYYY-MM-DDTHH-MM-SSZ.png (UTC; written under a temporary name, then "
        "renamed), for the controller's frame folder; at night it writes the dark sky.",
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
    _add_panel_camera_options(d)
    d.set_defaults(func=run_drive)


def _add_panel_camera_options(d: argparse.ArgumentParser) -> None:
    g = d.add_argument_group(
        "panel camera",
        "an emulated fisheye camera on the panel this drive turns (a clear sky; frames at "
        "night too: the dark sky)",
    )
    g.add_argument(
        "--panel-camera", metavar="DIR", type=Path, help="write its frames into DIR (created if missing)"
    )
    g.add_argument(
        "--site",
        nargs=2,
        type=float,
        metavar=("LAT", "LON"),
        help="where the panel stands, deg north and east (required with --panel-camera)",
    )
    g.add_argument(
        "--mount-offset",
        nargs="+",
        type=float,
        metavar="DEG",
        help="per axis, how far the panel sits off the drive's shaft, deg (default 0): "
        "the encoder sees the shaft, the camera and the sun the panel",
    )
    g.add_argument(
        "--camera-mount",
        nargs=3,
        type=float,
        metavar=("RX", "RY", "RZ"),
        default=(0.0, 0.0, 0.0),
        help="the camera's rotation on its panel, a rotation vector in the panel's frame, deg "
        "(default 0 0 0; 0 1 0: its axis 1 deg towards increasing azimuth or rotation; 0 0 180: "
        "upside down), for "
        "heliotrack calibrate fisheye mount",
    )
    g.add_argument(
        "--axis-azimuth",
        type=float,
        default=180.0,
        metavar="DEG",
        help="a row's axis azimuth, deg (default 180; one axis only)",
    )
    g.add_argument(
        "--axis-tilt",
        type=float,
        default=0.0,
        metavar="DEG",
        help="a row's axis tilt, deg (default 0; one axis only)",
    )
    g.add_argument(
        "--camera-interval",
        type=float,
        default=1.0,
        metavar="S",
        help="seconds between frames (default 1, >= 1)",
    )
    g.add_argument(
        "--keep", type=int, default=30, metavar="N", help="keep the N newest frames (default 30, >= 2)"
    )
    g.add_argument(
        "--panel-scale",
        type=float,
        default=0.5,
        metavar="X",
        help="image size / 640 x 480 (0.5: 320 x 240; up to 2)",
    )


def run_drive(args: argparse.Namespace) -> int:
    fw = firmware(args)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())

    camera = _start_panel_camera(args, fw)
    try:
        serve = _serve_canopen if args.protocol == "canopen" else _serve_modbus
        serve(args, fw, stop)
    finally:
        if camera is not None:
            camera.stop()  # before the report: that stays the last line on stderr
    _report(fw)
    return 0


def _serve_modbus(args: argparse.Namespace, fw, stop: threading.Event) -> None:
    """Modbus RTU on a pty, or Modbus TCP on 127.0.0.1."""
    from hil.modbus_server import ModbusServerThread
    from hil.pty import PtyLink

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
    offsets = _check_panel_camera_options(args)
    # wall time for nothing but its reports; physics, watchdog and uptime on its own ticks
    fw = DriveFirmware(axes, time.time, heartbeat_timeout=args.heartbeat_timeout, monotonic=time.monotonic)
    fw.mount_offsets = offsets
    return fw


def _check_panel_camera_options(args: argparse.Namespace) -> list[float]:
    """Check the panel camera's options (a one-line error for a bad one); returns the
    mounting offset per axis (deg)."""
    from hil.errors import HilError

    offsets = args.mount_offset if args.mount_offset is not None else [0.0] * args.axes
    if len(offsets) != args.axes:
        raise HilError(f"--mount-offset needs {args.axes} value(s) (one per axis), got {len(offsets)}")
    if not all(abs(d) <= 180.0 for d in offsets):  # NaN too
        raise HilError(f"--mount-offset must be within +-180 deg, got {' '.join(f'{d:g}' for d in offsets)}")
    if args.panel_camera is not None and args.site is None:
        raise HilError("--panel-camera needs --site LAT LON (deg north, east): the sun's place in the sky")
    if args.site is not None:
        lat, lon = args.site
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
            raise HilError(
                f"--site LAT LON: latitude within +-90 and longitude within +-180 deg, got {lat:g} {lon:g}"
            )
    if not all(abs(r) <= 180.0 for r in args.camera_mount):  # NaN too
        raise HilError(
            f"--camera-mount must be within +-180 deg, got {' '.join(f'{r:g}' for r in args.camera_mount)}"
        )
    if not math.isfinite(args.axis_azimuth):
        raise HilError(f"--axis-azimuth must be a finite angle in deg, got {args.axis_azimuth}")
    if not abs(args.axis_tilt) < 90.0:
        raise HilError(f"--axis-tilt must be within +-90 deg (exclusive), got {args.axis_tilt:g}")
    if not 1.0 <= args.camera_interval < math.inf:
        raise HilError(
            f"--camera-interval must be >= 1 s (frame names have 1-s resolution), got {args.camera_interval:g}"
        )
    if args.keep < 2:
        raise HilError(f"--keep must be >= 2 frames (a reader needs the newest whole), got {args.keep}")
    if not 0.1 <= args.panel_scale <= 2.0:
        raise HilError(f"--panel-scale must be within 0.1..2 (x 640 x 480 pixels), got {args.panel_scale:g}")
    return [float(d) for d in offsets]


def _start_panel_camera(args: argparse.Namespace, fw) -> PanelCameraWriter | None:
    """The panel camera's writer thread, started (None without --panel-camera)."""
    if args.panel_camera is None:
        return None
    from heliotrack.panel_camera_writer import PanelCameraWriter
    from hil.camera import Site
    from hil.errors import HilError
    from hil.panelcam import PanelCamera

    folder: Path = args.panel_camera
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HilError(f"--panel-camera: cannot create {folder}: {exc.strerror or exc}") from None
    kind = "dual-axis" if args.axes == 2 else "single-axis"
    cam = PanelCamera(
        kind,
        Site(args.site[0], args.site[1], 0.0),  # sea level: the sun's place hardly depends on it
        axis_azimuth=args.axis_azimuth,
        axis_tilt=args.axis_tilt,
        scale=args.panel_scale,
        noise=True,
        clouds=None,
        mount_deg=tuple(args.camera_mount),
    )
    lens = cam.scene.lens
    offsets = " ".join(f"{d:+.2f}" for d in fw.mount_offsets)
    print(
        f"panel camera: {folder}, {kind}, every {args.camera_interval:g} s, {lens.width}x{lens.height}, "
        f"keep {args.keep}, mount offset {offsets} deg"
        + (
            f", camera turned {' '.join(f'{r:+.2f}' for r in args.camera_mount)} deg on the panel"
            if any(args.camera_mount)
            else ""
        ),
        file=sys.stderr,
        flush=True,
    )
    writer = PanelCameraWriter(
        folder,
        lambda t, angles: cam.render(t, angles, 1.0),  # a clear sky: the sun never hidden
        fw.panel_angles,
        interval=args.camera_interval,
        keep=args.keep,
    )
    return writer.start()


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


def _serve_canopen(args: argparse.Namespace, fw, stop: threading.Event) -> None:
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
    finally:
        if adapter:
            adapter.stop()
            adapter.bus.shutdown()
        emulator.stop()
        if link:
            link.close()
