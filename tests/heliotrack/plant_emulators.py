"""A plant of standalone emulators in other processes, for ``heliotrack run`` and ``check``.

Three ``heliotrack hil drive`` processes (Modbus RTU on a pty, Modbus TCP on 127.0.0.1,
CANopen behind an slcan pty), a plant file that names them as real devices, a video file
of rendered hotspot frames as the camera, and readers that ask the emulators themselves
(minimalmodbus, pymodbus, canopen) what their axes do, never the controller.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from firmware_protocol import Mode, Status, register
from firmware_protocol.canopen import mirror_index

REPO = Path(__file__).resolve().parents[2]
HELIOTRACK = [sys.executable, "-m", "heliotrack.cli"]
EDS = REPO / "firmware_protocol" / "generated" / "heliotrack_drive.eds"
BUNDLE = REPO / "config" / "calibration" / "recommended.toml"


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def heliotrack(*args: str, cwd: Path | None = None) -> subprocess.Popen:
    """``heliotrack ARGS...`` in a process of its own, its output piped as text."""
    return subprocess.Popen(
        [*HELIOTRACK, *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env()
    )


@dataclass
class Drive:
    """One emulator process and how to reach it."""

    proc: subprocess.Popen
    kind: str  # "rtu", "tcp", "canopen"
    address: str  # pty path, or TCP port
    device_id: int
    axes: int

    def stop(self) -> str:
        """SIGTERM; returns its stderr (the last line gives each axis's angle and mode)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            _, err = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return err


def start_drive(kind: str, device_id: int, axes: int) -> Drive:
    args = [*HELIOTRACK, "hil", "drive", "--id", str(device_id), "--axes", str(axes), "--max-speed", "10"]
    args += {
        "rtu": ["--link", "pty"],
        "tcp": ["--link", "tcp"],
        "canopen": ["--link", "pty", "--protocol", "canopen"],
    }[kind]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env())
    return Drive(proc, kind, "", device_id, axes)


def ready(drive: Drive) -> Drive:
    first = drive.proc.stdout.readline().strip()
    assert first.startswith(("PTY ", "TCP ")), (first, drive.proc.stderr.read() if drive.proc.poll() else "")
    drive.address = (
        first.split(" ", 1)[1].rsplit(":", 1)[-1] if drive.kind == "tcp" else first.split(" ", 1)[1]
    )
    return drive


@dataclass
class Plant:
    drives: dict[str, Drive] = field(default_factory=dict)

    def stop(self) -> None:
        for d in self.drives.values():
            d.stop()


def start_plant() -> Plant:
    """A dual-axis tracker on RTU (id 1), a row on TCP (id 2), a row on CANopen (node 20)."""
    started = {
        "dual-1": start_drive("rtu", 1, 2),
        "row-tcp": start_drive("tcp", 2, 1),
        "row-can": start_drive("canopen", 20, 1),
    }
    return Plant({name: ready(d) for name, d in started.items()})


def daytime_site(t: float) -> tuple[float, float]:
    """(latitude, longitude) where the sun is high at ``t``: local noon near the equinox line."""
    lon = ((12.0 - (t % 86400) / 3600.0) * 15.0 + 180.0) % 360.0 - 180.0
    return 20.0, round(lon, 4)


def render_video(path: Path, t0: float, frames: int, dt: float, site: tuple[float, float]) -> Path:
    """A lossless video of the world's hotspot camera at ``t0, t0 + dt, ...`` (fps 1/dt)."""
    from hil.camera import Site, profile, render_frame

    scn = profile("recommended", tilt_deg=0.3).with_(site=Site(site[0], site[1], 100.0))
    writer = None
    for k in range(frames):
        image = render_frame(scn, t0 + k * dt).image
        if writer is None:
            h, w = image.shape
            writer = cv2.VideoWriter(
                str(path), cv2.VideoWriter_fourcc(*"FFV1"), 1.0 / dt, (w, h), isColor=False
            )
        writer.write(image)
    assert writer is not None
    writer.release()
    return path


def plant_toml(
    path: Path,
    plant: Plant,
    site: tuple[float, float],
    *,
    period: float = 1.0,
    heartbeat: float = 3.0,
    video: Path | None = None,
    sunspec: bool = False,
) -> Path:
    d = plant.drives
    camera = "\n[sunspec]\nenabled = true\nport = 0\n" if sunspec else ""
    if video is not None:
        camera += f"""
[hotspot]
calibration = "{BUNDLE}"
frames = "{video}"

[sunpath]
site_known = true
"""
    path.write_text(
        f"""
[site]
name = "test plant"
latitude = {site[0]}
longitude = {site[1]}
altitude = 100.0

[control]
period_s = {period}
heartbeat_timeout_s = {heartbeat}
sun_source = "{"hotspot" if video else "ephemeris"}"

[[links]]
name = "rs485"
kind = "modbus-rtu"
port = "{d["dual-1"].address}"

[[links]]
name = "lan"
kind = "modbus-tcp"
host = "127.0.0.1"
tcp_port = {d["row-tcp"].address}

[[links]]
name = "can"
kind = "canopen"
interface = "slcan"
channel = "{d["row-can"].address}"
bitrate = 500000

[[trackers]]
name = "dual-1"
type = "dual-axis"
link = "rs485"
device_id = 1

[[trackers]]
name = "row-tcp"
type = "single-axis"
link = "lan"
device_id = 2
max_angle = 55.0
safe_position = "hold"

[[trackers]]
name = "row-can"
type = "single-axis"
link = "can"
device_id = 20
max_angle = 55.0
{camera}"""
    )
    return path


@dataclass(frozen=True)
class AxisReading:
    actual_deg: float
    target_deg: float
    mode: Mode
    status: Status


def read_axes(drive: Drive) -> list[AxisReading]:
    """Ask the emulator itself (an independent master per protocol)."""
    if drive.kind == "canopen":
        return _read_canopen(drive)
    if drive.kind == "rtu":
        import minimalmodbus

        m = minimalmodbus.Instrument(drive.address, drive.device_id)
        m.serial.baudrate, m.serial.timeout = 115200, 0.5
        try:
            return [_axis(lambda a, n: m.read_registers(a, n), k) for k in range(drive.axes)]
        finally:
            m.serial.close()
    from pymodbus.client import ModbusTcpClient

    c = ModbusTcpClient("127.0.0.1", port=int(drive.address), timeout=1)
    assert c.connect()
    try:
        return [
            _axis(lambda a, n: c.read_holding_registers(a, count=n, device_id=drive.device_id).registers, k)
            for k in range(drive.axes)
        ]
    finally:
        c.close()


def _axis(read, k: int) -> AxisReading:
    from firmware_protocol import decode

    def value(name: str) -> float:
        reg = register(name)
        return float(decode(reg, read(reg.address(k), reg.words)))

    return AxisReading(
        value("ACTUAL_ANGLE"), value("TARGET_ANGLE"), Mode(int(value("MODE"))), Status(int(value("STATUS")))
    )


def _read_canopen(drive: Drive, attempts: int = 3) -> list[AxisReading]:
    """SDO reads through the emulator's slcan pty (a new adapter connection each time: a
    read that fails while the previous client lets go is tried again)."""
    for attempt in range(attempts):
        try:
            return _read_canopen_once(drive)
        except Exception:  # noqa: BLE001 - python-can and canopen raise many kinds
            if attempt == attempts - 1:
                raise
            time.sleep(0.2)
    raise AssertionError("unreachable")


def _read_canopen_once(drive: Drive) -> list[AxisReading]:
    import canopen

    network = canopen.Network()
    network.connect(interface="slcan", channel=drive.address, sleep_after_open=0, bitrate=500000)
    try:
        out = []
        for k in range(drive.axes):
            node = canopen.RemoteNode(drive.device_id + k, str(EDS))
            network.add_node(node)

            def value(name: str, node=node) -> float:
                reg = register(name)
                return node.sdo[mirror_index(reg)].raw * reg.scale

            out.append(
                AxisReading(
                    node.sdo[0x6064].raw * register("ACTUAL_ANGLE").scale,
                    value("TARGET_ANGLE"),
                    Mode(int(value("MODE"))),
                    Status(int(value("STATUS"))),
                )
            )
        return out
    finally:
        network.disconnect()


def wait_for(predicate, timeout: float, step: float = 0.1):
    """Poll ``predicate()`` until it returns something truthy; returns it (or the last)."""
    deadline = time.monotonic() + timeout
    while True:
        got = predicate()
        if got or time.monotonic() >= deadline:
            return got
        time.sleep(step)


def zenith_sun_site(t: float) -> tuple[float, float]:
    """(latitude, longitude) in deg where the sun stands near the zenith at POSIX ``t``."""
    import pvlib

    doy = datetime.fromtimestamp(t, UTC).timetuple().tm_yday
    lat = float(np.degrees(pvlib.solarposition.declination_spencer71(doy)))
    eot_min = float(pvlib.solarposition.equation_of_time_spencer71(doy))
    lon = ((12.0 - (t % 86400) / 3600.0 - eot_min / 60.0) * 15.0 + 180.0) % 360.0 - 180.0
    return round(lat, 4), round(lon, 4)


@dataclass
class CameraDrive:
    proc: subprocess.Popen
    port: int  # Modbus TCP on 127.0.0.1
    site: tuple[float, float]  # (latitude, longitude), deg


def start_camera_drive(folder: Path, *extra: str) -> CameraDrive:
    """``hil drive --link tcp --axes 1 --panel-camera folder ...``, its first line read."""
    site = zenith_sun_site(time.time())
    proc = subprocess.Popen(
        [*HELIOTRACK, "hil", "drive", "--link", "tcp", "--axes", "1", "--heartbeat-timeout", "0"]
        + ["--panel-camera", str(folder), "--site", str(site[0]), str(site[1]), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env(),
    )
    first = proc.stdout.readline().strip()
    assert first.startswith("TCP 127.0.0.1:"), (first, proc.stderr.read() if proc.poll() is not None else "")
    return CameraDrive(proc, int(first.rsplit(":", 1)[1]), site)
