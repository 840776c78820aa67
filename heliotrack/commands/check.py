"""``heliotrack check``: what a commissioning engineer runs first.

Validates the plant file, opens every link and asks every configured device who it is: each
drive its axis count, protocol and firmware versions, uptime, the round-trip time of its
requests, fault word and position; the pyranometer and the anemometer a reading; the
camera a frame (its size against the calibration bundle's; the sky camera's sun against
where the sun must be).  One row per device, printed as soon as it is known: ``ok`` and
what the device said, or what failed.  Exit 0 only if every device answered, 1 otherwise
(2 for a bad file).

Connecting to a drive is what ``run`` does at start-up (CANopen: NMT start and operation
enabled, holding its position); no target is written and nothing is configured.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from heliotrack.logs import add_log_options

if TYPE_CHECKING:
    from controller.calibration.fisheye_bundle import FisheyeBundle
    from controller.clock import Clock
    from controller.config import Config, TrackerConfig
    from controller.sun.camera import CameraFrame

log = logging.getLogger("heliotrack.check")

#: One device may take this long at most (a CANopen drive's start takes a few SDOs).
DEVICE_TIMEOUT_S = 30.0
#: A live camera has this long to deliver a first frame.
CAMERA_TIMEOUT_S = 10.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="ask every configured device who it is (commissioning)",
        description="Validate a plant file, open every link and ask every drive, sensor and "
        "the camera who it is; one row per device, 'ok' or what failed.  Exit 0 only if "
        "every device answered.",
    )
    p.add_argument("--config", type=Path, required=True, help="plant TOML")
    add_log_options(p, top_level=False)
    p.set_defaults(func=run, default_log_level="WARNING")


@dataclass
class Row:
    device: str
    where: str
    ok: bool
    detail: str


def run(args: argparse.Namespace) -> int:
    from heliotrack.bus_claims import claim_buses
    from heliotrack.runtime import load_plant

    config = load_plant(args.config, "check")
    rows: list[Row] = []
    try:
        with claim_buses(config.links):  # check writes each drive's configuration: not beside a run
            asyncio.run(check_plant(config, out=sys.stdout, rows=rows))
    except (KeyboardInterrupt, asyncio.CancelledError):  # a second Ctrl-C: the rows so far
        pass
    from controller.clock import RealClock

    total = len(_devices(config, RealClock()))
    if len(rows) < total:  # Ctrl-C: not a verdict on the devices left out
        print(f"check interrupted: {len(rows)} of {total} device(s) checked", flush=True)
        return 130
    failed = [r for r in rows if not r.ok]
    print(
        f"{len(rows) - len(failed)} of {len(rows)} device(s) ok"
        + (f"; {len(failed)} failed" if failed else "")
    )
    return 1 if failed else 0


def _devices(config: Config, clock: Clock) -> list[tuple[str, str, Callable[[], Awaitable]]]:
    """(device, where, its check) for every device of ``config``, in the order of the rows."""
    links = config.links_by_name
    out: list[tuple[str, str, Callable[[], Awaitable]]] = []
    for tr in config.trackers:
        link = links[tr.link]
        out.append((tr.name, _where(link, tr.device_id), partial(_drive, config, tr, link)))
    if config.pyranometer is not None:
        p = config.pyranometer
        out.append(("pyranometer", _where(links[p.link], p.device_id), partial(_pyranometer, config, clock)))
    if config.wind is not None:
        w = config.wind
        out.append(("anemometer", _where(links[w.link], w.device_id), partial(_anemometer, config, clock)))
    from heliotrack.panel_loop import looped_trackers

    for tracker in looped_trackers(config):
        assert config.closedloop is not None
        spec = config.closedloop.camera(tracker)
        out.append(
            (f"{tracker}/camera", spec, partial(asyncio.to_thread, _panel_camera, config, clock, tracker))
        )
    cameras = {"hotspot": ("hotspot",), "fisheye": ("fisheye",), "fused": ("hotspot", "fisheye")}
    for name in cameras.get(config.control.sun_source, ()):
        label = "camera" if name == "hotspot" else name
        frames = getattr(config, name).frames
        out.append((label, frames, partial(asyncio.to_thread, _camera, config, clock, name)))
    return out


async def check_plant(
    config: Config, clock: Clock | None = None, out: TextIO | None = None, rows: list[Row] | None = None
) -> list[Row]:
    """Check every device of ``config`` in turn; rows are printed to ``out`` as they come
    and appended to ``rows`` (the rows so far, when a second Ctrl-C cancels the check).

    The first Ctrl-C (SIGINT) stops the check at once: the device being checked is given
    up (its link closed), and the rows are those of the devices checked before.
    """
    from controller.clock import RealClock
    from heliotrack.interrupt import stop_on_sigint

    clock = clock or RealClock()
    width = max([len(t.name) for t in config.trackers] + [len("pyranometer"), len("anemometer")]) + 2
    rows = [] if rows is None else rows

    def emit(row: Row) -> None:
        rows.append(row)
        if out is not None:
            status = "ok" if row.ok else "FAILED"
            print(f"{row.device:<{width}}{row.where:<34} {status:<7}{row.detail}", file=out, flush=True)

    if out is not None:
        print(f"{'DEVICE':<{width}}{'WHERE':<34} {'RESULT':<7}DETAIL", file=out, flush=True)
    stop = asyncio.Event()
    with stop_on_sigint(stop):
        for device, where, check in _devices(config, clock):
            if stop.is_set():
                break
            row = await _unless_stopped(stop, _guarded(device, where, check()))
            if row is not None:
                emit(row)
    return rows


async def _unless_stopped(stop: asyncio.Event, check: Awaitable[Row]) -> Row | None:
    """The row of ``check``, or None when ``stop`` is set first (the check is cancelled,
    which closes its link: a drive's check holds a CANopen node enabled)."""
    task = asyncio.ensure_future(check)
    stopper = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait({task, stopper}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        stopper.cancel()
        if not task.done():
            task.cancel()
            await asyncio.wait({task})
    return None if task.cancelled() else task.result()


def _where(link, device_id: int) -> str:
    from controller.drives.modbus.client import endpoint

    if link.kind == "canopen":
        return f"{link.interface}:{link.channel} node {device_id}"
    return f"{endpoint(link)} id {device_id}"


async def _guarded(device: str, where: str, check) -> Row:
    """Run one device's check; a failure is a row, never an exception."""
    from controller.drives.base import DriveCommError, DriveNoAnswer
    from controller.errors import UserError

    try:
        ok, detail = await asyncio.wait_for(check, DEVICE_TIMEOUT_S)
    except DriveNoAnswer as exc:
        ok, detail = False, f"no answer on {exc.label} after {exc.attempts} tries"
    except TimeoutError:
        ok, detail = False, f"no answer on {where} within {DEVICE_TIMEOUT_S:g} s"
    except (DriveCommError, UserError, OSError) as exc:
        ok, detail = False, str(exc)
    except Exception as exc:  # noqa: BLE001 - a library's surprise is this device's row, not the end of check
        log.debug("%s: %s", device, exc, exc_info=exc)
        ok, detail = False, f"unexpected {type(exc).__name__}: {exc}"
    return Row(device, where, ok, detail)


async def _drive(config: Config, tr: TrackerConfig, link) -> tuple[bool, str]:
    from controller.drives.registry import open_drive
    from firmware_protocol import PROTOCOL_VERSION, Fault, Mode, Status

    drive = open_drive(link, tr.device_id)
    try:
        await drive.connect()
        count = drive.axis_count
        ident = await drive.identify()
        state = await drive.read_state()
        held = await drive.read_configuration()
        # every request answered so far (Modbus reads, CANopen SDOs; a CANopen state comes
        # from TPDOs, no request): what the link's timeout_s and the period must allow
        rtts = sorted(drive.stats.latencies_s)
    finally:
        await drive.close()
    problems = []
    if count != tr.axes:
        # another drive at that address, most likely: run would drive one of its axes (or refuse)
        have = f"{count} axis" if count == 1 else f"{count} axes"
        verb = "drives" if count > tr.axes else "needs"
        problems.append(f"drive has {have}, a {tr.type} tracker {verb} {tr.axes}: wrong device_id?")
    parts = [f"{count} axis" if count == 1 else f"{count} axes"]
    if ident is None:
        parts.append("identity not reported by this link kind")
    else:
        v = ident.version_text
        if ident.protocol_version >> 8 != PROTOCOL_VERSION >> 8:
            problems.append(
                f"protocol version {ident.protocol_version >> 8}, expected {PROTOCOL_VERSION >> 8}"
            )
        parts.append(f"protocol {v(ident.protocol_version)}, firmware {v(ident.firmware_version)}")
        parts.append(f"up {_duration(ident.uptime_s)}")
    if rtts:
        parts.append(f"rtt {_ms(rtts[len(rtts) // 2])} (max {_ms(rtts[-1])})")
    faults = [f"axis {k} {a.fault.name}" for k, a in enumerate(state.axes) if a.status & Status.FAULT]
    if faults:
        problems.append("fault " + ", ".join(faults))
    else:
        parts.append("no fault")
    held_locally = [str(k) for k, a in enumerate(state.axes) if a.mode == Mode.MAINTENANCE]
    if held_locally:  # run leaves MAINTENANCE to whoever set it: this drive would never track
        problems.append(
            f"axis {', '.join(held_locally)} in MAINTENANCE (local service mode): run will not move it"
        )
    if any(a.fault != Fault.NONE and not a.status & Status.FAULT for a in state.axes):
        parts.append("a cleared fault code remains")
    pos = ", ".join(f"{a.actual_deg:.2f}" for a in state.axes)
    modes = ", ".join(a.mode.name + (" COMM_LOST" if a.status & Status.COMM_LOST else "") for a in state.axes)
    parts.append(f"at {pos} deg ({modes})")
    if held is not None:
        parts.append(_configuration(config, tr, held))
    text = "; ".join(parts)
    return (False, "; ".join(problems) + f" ({text})") if problems else (True, text)


def _configuration(config: Config, tr: TrackerConfig, held) -> str:
    """The watchdog, limits and stow angles the drive holds, and what ``run`` will write
    where the plant file says otherwise (not a failure: ``run`` configures every drive)."""
    from controller.drives.configuration import Tolerances, differences
    from controller.safety import SafetyState, drive_stow_angles

    stows = drive_stow_angles(SafetyState(config.wind, config.stow, 0.0), tr)
    diffs = differences(
        held,
        Tolerances(0.1, 0.001, 0.01),  # the coarsest step of the backends' units
        heartbeat_timeout_s=config.control.heartbeat_timeout_s,
        soft_limits=tr.soft_limits,
        stow_angles=stows,
    )
    if not diffs:
        return held.describe() + " (as the plant file has it)"
    return held.describe() + "; run writes " + ", ".join(f"{what} {wanted}" for what, _, wanted in diffs)


def _ms(s: float) -> str:
    """A round-trip time: tenths below 10 ms (a pty or a LAN answers in well under one)."""
    return f"{s * 1000:.1f} ms" if s < 0.01 else f"{s * 1000:.0f} ms"


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


async def _pyranometer(config: Config, clock: Clock) -> tuple[bool, str]:
    from heliotrack.devices import open_pyranometer

    sensor = open_pyranometer(config)
    assert sensor is not None
    try:
        sample = await sensor.read(clock.now())
    finally:
        await sensor.close()
    return True, f"{sample.ghi_w_m2:.0f} W/m2"


async def _anemometer(config: Config, clock: Clock) -> tuple[bool, str]:
    from heliotrack.devices import open_anemometer

    sensor = open_anemometer(config)
    assert sensor is not None
    try:
        s = await sensor.read(clock.now())
    finally:
        await sensor.close()
    return (
        True,
        f"wind {s.speed_m_s:.1f} m/s, gust {s.gust_m_s:.1f} m/s, 10-min mean {s.mean_10min_m_s:.1f} m/s",
    )


def _camera(config: Config, clock: Clock, name: str = "hotspot") -> tuple[bool, str]:
    """A frame from camera ``name`` (``hotspot``, ``fisheye``), and its size against its
    calibration bundle's."""
    from controller.calibration.bundle import load_bundle
    from controller.calibration.fisheye_bundle import FisheyeBundle, load_fisheye_bundle
    from controller.sun.camera import grey8, judge_frame
    from heliotrack.sun_sources import open_frame_source

    hs = getattr(config, name)
    assert hs is not None
    bundle = load_fisheye_bundle(hs.calibration) if name == "fisheye" else load_bundle(hs.calibration)
    width, height = bundle.camera.width, bundle.camera.height
    frame, text = _first_frame(open_frame_source(hs.frames, clock, f"{name}.frames"), hs.frames, clock)
    if frame is None:
        return False, text
    h, w = frame.image.shape[:2]
    if (w, h) != (width, height):
        return False, f"{text}, the calibration bundle expects {width}x{height}"
    grey = grey8(frame.image)
    judged = judge_frame(grey) if grey is not None else "unsupported_image_format"
    if judged or not isinstance(bundle, FisheyeBundle):
        return True, text + (f"; {judged.replace('_', ' ')}" if judged else "")
    ok, said = _sky_camera_orientation(config, bundle, frame)
    return ok, f"{text}; {said}"


def _first_frame(source, spec: str, clock: Clock) -> tuple[CameraFrame | None, str]:
    """(the first frame of ``source``, "frame WxH (name)"), or (None, why not); closes it."""
    try:
        frame = source.first_frame(clock.now(), CAMERA_TIMEOUT_S)
    finally:
        source.close()
    if frame is None:
        return None, f"no frame from {spec} within {CAMERA_TIMEOUT_S:g} s"
    h, w = frame.image.shape[:2]
    return frame, f"frame {w}x{h}" + (f" ({frame.name})" if frame.name else "")


def _panel_camera(config: Config, clock: Clock, tracker: str) -> tuple[bool, str]:
    """A frame from ``tracker``'s panel camera (``[closedloop] frames``): its size against
    the ``[closedloop] calibration`` lens, its age, and where the sun lies from the panel's
    normal (the camera's axis) when it is in view."""
    import math

    from controller.calibration.fisheye_bundle import load_fisheye_bundle
    from controller.vision.fisheye import FisheyeEstimator
    from heliotrack.panel_loop import open_panel_cameras

    cl = config.closedloop
    assert cl is not None
    bundle = load_fisheye_bundle(cl.lens(tracker))
    source = open_panel_cameras(config, clock, only=tracker)[tracker]
    frame, text = _first_frame(source, cl.camera(tracker), clock)
    if frame is None:
        return False, text
    h, w = frame.image.shape[:2]
    if (w, h) != (bundle.camera.width, bundle.camera.height):
        return False, f"{text}, the [closedloop] lens expects {bundle.camera.width}x{bundle.camera.height}"
    age = clock.now() - frame.time
    if age > config.control.period_s:  # the loop uses only frames taken since its last setpoint
        return (
            False,
            f"{text}, {age:.0f} s old: the loop needs one at least every {config.control.period_s:g} s",
        )
    res = FisheyeEstimator(bundle).estimate_image(frame.image, None)
    if not res.found or res.d_cam is None:
        return True, f"{text}; no sun in view ({res.reason})"
    d = res.d_cam if bundle.mount is None else bundle.mount.matrix @ res.d_cam
    off = math.degrees(math.acos(max(-1.0, min(1.0, float(d[2])))))
    mount = (
        ""
        if bundle.mount is not None
        else " (no [mount] in the lens bundle: the camera's axis taken as the normal)"
    )
    return True, f"{text}; the sun {off:.2f} deg from the panel's normal{mount}"


def _sky_camera_orientation(config: Config, bundle: FisheyeBundle, frame: CameraFrame) -> tuple[bool, str]:
    """The sky camera's ``frame`` read by its estimator, with the plant's site as the loop
    reads it: how far the sun it finds lies from where the sun must be, or, where the
    ephemeris gate refused its glare, that offset, which says the camera has moved since its
    orientation was calibrated (or the site or the clock is off; a failed row).  With no
    sun in view (night, cloud) there is nothing to check."""
    import math

    from controller.sun.types import angle_between_deg, azel_to_enu
    from controller.vision.fisheye import FisheyeEstimator
    from heliotrack.sun_sources import plant_site_bundle

    est = FisheyeEstimator(plant_site_bundle(config, bundle))
    res = est.estimate_image(frame.image, frame.time)
    if res.found and res.az_deg is not None and res.el_deg is not None:
        if est.ephemeris is None:  # no site known, or a bundle without [orientation]
            missing = "no site" if est.R is not None else "no orientation in its bundle"
            return True, f"the sun found ({missing} to check the camera's orientation against)"
        off = float(
            angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), est.ephemeris.direction(frame.time))
        )
        return True, f"the sun found {off:.2f} deg from where it must be"
    glare = res.extra.get("glare_offset_deg")
    if glare is not None:
        along, up = glare
        return False, (
            f"the sun-like glare nearest the sun is {math.hypot(along, up):.2f} deg from where the sun "
            f"must be ({along:+.2f} deg along the horizon, {up:+.2f} up): if the sun was in a clear sky, "
            "the camera has moved since its orientation was calibrated (heliotrack calibrate fisheye "
            "orientation), or the plant's site or the clock is off"
        )
    return True, f"no sun to check its orientation against ({res.reason})"
