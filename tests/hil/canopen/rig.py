"""Test rig: emulated CANopen drives on a private virtual bus, and a canopen master on it."""

from __future__ import annotations

import time
import uuid
from contextlib import contextmanager

import canopen

from hil.canopen import CanopenNetworkEmulator, object_dictionary
from hil.drive import AxisParams, DriveFirmware


def one_axis(**kw) -> list[AxisParams]:
    base = {
        "max_speed": 10.0,
        "accel": 50.0,
        "soft_min": -60.0,
        "soft_max": 60.0,
        "hard_min": -65.0,
        "hard_max": 65.0,
        "stow_angle": 0.0,
        "initial_angle": 0.0,
    }
    base.update(kw)
    return [AxisParams(**base)]


def two_axes() -> list[AxisParams]:
    return [
        AxisParams(
            max_speed=10.0,
            accel=50.0,
            soft_min=0.0,
            soft_max=360.0,
            hard_min=-5.0,
            hard_max=365.0,
            stow_angle=180.0,
            initial_angle=180.0,
        ),
        AxisParams(
            max_speed=10.0,
            accel=50.0,
            soft_min=0.0,
            soft_max=90.0,
            hard_min=-5.0,
            hard_max=95.0,
            stow_angle=90.0,
            initial_angle=90.0,
        ),
    ]


def channel() -> str:
    """A virtual channel no other test shares."""
    return f"ht-test-{uuid.uuid4().hex[:8]}"


@contextmanager
def emulated(
    axes=None, node_id: int = 5, now=time.time, heartbeat_timeout: float = 0.0, period_s: float = 0.01
):
    """(firmware, emulator, channel) with the drive on a fresh virtual bus."""
    ch = channel()
    fw = DriveFirmware(axes or one_axis(), now, heartbeat_timeout=heartbeat_timeout)
    emu = CanopenNetworkEmulator(ch, period_s=period_s).start()
    try:
        emu.add_drive(fw, node_id)
        yield fw, emu, ch
    finally:
        emu.stop()


@contextmanager
def master(ch: str):
    """A canopen Network on ``ch`` (the master side)."""
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.05  # disconnect waits for one notifier cycle
    net.connect(interface="virtual", channel=ch)
    try:
        yield net
    finally:
        net.disconnect()


def node402(net: canopen.Network, node_id: int) -> canopen.BaseNode402:
    node = canopen.BaseNode402(node_id, object_dictionary(node_id))
    net.add_node(node)
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    return node


def wait_for(predicate, timeout: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()
