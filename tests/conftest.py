"""Shared fixtures: a drive emulator served on a real pty, and a config factory."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from controller.clock import SimClock
from hil.drive import AxisParams, DriveFirmware
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink

REPO = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = REPO / "config" / "hil-default.toml"


@pytest.fixture
def sim_clock():
    return SimClock(1_710_900_000.0)


def two_axes(**kw) -> list[AxisParams]:
    base = dict(soft_min=0.0, soft_max=360.0, hard_min=-5.0, hard_max=365.0)
    base.update(kw)
    el = dict(base, soft_min=0.0, soft_max=90.0, hard_min=-5.0, hard_max=95.0)
    return [AxisParams(**base, stow_angle=180.0, initial_angle=180.0),
            AxisParams(**el, stow_angle=90.0, initial_angle=90.0)]


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
