"""Shared fixtures: a drive emulator served on a real pty, and a config factory."""

from __future__ import annotations

import asyncio
import atexit
import os
import shutil
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest

from controller.clock import SimClock
from hil.drive import AxisParams, DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink

REPO = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = REPO / "config" / "hil-default.toml"

# The bus locks of the session's runs and checks (their ports are random) go to a folder
# of its own, inherited by the processes it starts, not to the machine's /run/lock
_LOCKS = tempfile.mkdtemp(prefix="heliotrack-test-locks-")
atexit.register(shutil.rmtree, _LOCKS, ignore_errors=True)
os.environ["HELIOTRACK_LOCK_DIR"] = _LOCKS


@pytest.fixture
def sim_clock():
    return SimClock(1_710_900_000.0)


def two_axes(**kw) -> list[AxisParams]:
    base = dict(soft_min=0.0, soft_max=360.0, hard_min=-5.0, hard_max=365.0)
    base.update(kw)
    el = dict(base, soft_min=0.0, soft_max=90.0, hard_min=-5.0, hard_max=95.0)
    return [
        AxisParams(**base, stow_angle=180.0, initial_angle=180.0),
        AxisParams(**el, stow_angle=90.0, initial_angle=90.0),
    ]


@pytest.fixture
def pty_drive(sim_clock):
    """(firmware, pty path, clock): a two-axis drive, id 1, served over Modbus RTU on a pty."""
    fw = DriveFirmware(two_axes(), sim_clock.now, heartbeat_timeout=30.0)
    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        yield fw, link.path, sim_clock


@pytest.fixture
def wall_pty_drive():
    """A two-axis drive on the wall clock, for real-time behaviour."""
    fw = DriveFirmware(two_axes(), time.time, heartbeat_timeout=1.0)
    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        yield fw, link.path


@pytest.fixture
def default_plant():
    """The default config's trackers driven by a Controller over one RTU pty on a
    simulated clock (mid-morning, 1 June).

    Yields (run, controller, firmwares by tracker name, clock, config); ``run`` runs a
    coroutine on the fixture's event loop (pymodbus clients belong to their loop).
    """
    from dataclasses import replace

    from controller.drives.registry import open_drive
    from controller.loop import Controller
    from controller.sun.source import EphemerisSource
    from heliotrack.scenario import load_scenario

    cfg = load_scenario(DEFAULT_CONFIG)
    clock = SimClock(datetime(2024, 6, 1, 8, 0, tzinfo=UTC))  # ~11:15 solar time
    fws = {
        tr.name: DriveFirmware(
            [
                AxisParams(
                    soft_min=lo, soft_max=hi, hard_min=lo - 5, hard_max=hi + 5, stow_angle=s, initial_angle=s
                )
                for (lo, hi), s in zip(tr.soft_limits, tr.stow_angles)
            ],
            clock.now,
            cfg.control.heartbeat_timeout_s,
        )
        for tr in cfg.trackers
    }
    loop = asyncio.new_event_loop()
    with (
        PtyLink.open() as link,
        ModbusServerThread({tr.device_id: fws[tr.name] for tr in cfg.trackers}, serial_url=link.url),
    ):

        async def make():
            rtu = replace(cfg.links[0], port=link.path, timeout_s=0.3, retries=0)
            drives = {tr.name: open_drive(rtu, tr.device_id) for tr in cfg.trackers}
            ctl = Controller(cfg, drives, EphemerisSource(cfg.site), clock)
            await ctl.start()
            return ctl

        ctl = loop.run_until_complete(make())
        yield loop.run_until_complete, ctl, fws, clock, cfg
        loop.run_until_complete(ctl.close())
    loop.close()
