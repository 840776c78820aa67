"""A CANopen row driven by the real loop while another party acts on its drive: a service
tool's NMT stop or CiA 402 quick stop (held, never overridden), an NMT reset of the node's
communication (configured again), a 402 fault the heliotrack mirror does not show, another
device answering at the node id, a firmware latching other targets.  Each was an audit's
finding on a private virtual bus with the HIL's CANopen emulator."""

from __future__ import annotations

import asyncio
import time
import uuid
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import can
import pytest

from controller.clock import SimClock
from controller.drives.registry import open_drive
from controller.health import Health
from controller.loop import Controller
from controller.sun.source import EphemerisSource
from firmware_protocol import Command, Fault, Mode, encode, register
from firmware_protocol.cia402 import State402
from heliotrack.scenario import load_scenario
from hil.canopen import CanopenNetworkEmulator
from hil.drive import AxisParams, DriveFirmware

SCENARIO = Path(__file__).resolve().parents[2] / "config" / "hil-canopen.toml"
NODE = 3


class Row:
    """row-1 of the CANopen scenario at node 3, alone on a private bus, and a second master
    (a raw python-can handle) on the same bus."""

    def __init__(self, axes: int = 1) -> None:
        cfg = load_scenario(SCENARIO)
        self.ch = f"held-{uuid.uuid4().hex[:8]}"
        link = replace(cfg.links[0], channel=self.ch, timeout_s=0.3, retries=1)
        row = replace(next(t for t in cfg.trackers if t.name == "row-1"), device_id=NODE)
        self.cfg = replace(cfg, links=(link,), trackers=(row,))
        self.clock = SimClock(datetime(2024, 3, 20, 8, 0, tzinfo=UTC))
        axis = AxisParams(
            soft_min=-60,
            soft_max=60,
            hard_min=-65,
            hard_max=65,
            stow_angle=0.0,
            initial_angle=0.0,
            max_speed=1.0,
            stall_time=0.1,
        )
        self.fw = DriveFirmware(
            [axis] * axes,
            self.clock.now,
            heartbeat_timeout=0.0,
        )
        self.emu = CanopenNetworkEmulator(self.ch, period_s=0.01).start()
        self.emulated = self.emu.add_drive(self.fw, NODE)
        self.loop = asyncio.new_event_loop()
        self.drive = open_drive(link, NODE)
        self.ctl = Controller(self.cfg, {"row-1": self.drive}, EphemerisSource(self.cfg.site), self.clock)
        self.tr = self.ctl.trackers[0]
        self.other = can.Bus(interface="virtual", channel=self.ch)

    def cycle(self):
        self.clock.sleep(self.cfg.control.period_s)
        return self.loop.run_until_complete(self.ctl.cycle())[0]

    def send(self, cob_id: int, data: bytes) -> None:
        """A frame from the other master; then give the emulator time to act on it."""
        self.other.send(can.Message(arbitration_id=cob_id, data=data, is_extended_id=False))
        time.sleep(0.3)

    def node(self):
        return self.emulated.nodes[0]

    def close(self) -> None:
        try:
            self.loop.run_until_complete(self.ctl.close())
        finally:
            self.other.shutdown()
            self.emu.stop()
            self.loop.close()


@pytest.fixture
def row():
    r = Row()
    r.loop.run_until_complete(r.ctl.start())
    try:
        yield r
    finally:
        r.close()


def seen(r: Row, nmt_state: str, timeout: float = 5.0) -> bool:
    """The master has heard the node's heartbeat say ``nmt_state``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if r.drive.axes and r.drive.axes[0].node.nmt.state == nmt_state:
            return True
        time.sleep(0.05)
    return False


def reboots(r: Row) -> int:
    return sum(1 for e in r.ctl.events if e.get("kind") == "drive_reboot")


def test_a_node_stopped_by_another_master_is_held_not_started_again(row):
    """It had been started again at once, logged as a reboot."""
    assert row.cycle().health == "ok"
    row.send(0x000, bytes([0x02, NODE]))  # NMT stop
    assert seen(row, "STOPPED")  # its next heartbeat says so (one a second)
    for _ in range(4):
        rec = row.cycle()
        assert rec.health == "degraded", rec
        assert "put in NMT STOPPED by another master" in rec.health_reason
    assert row.node().node.nmt.state == "STOPPED"  # nobody started it again
    assert row.tr.health.state == Health.DEGRADED and row.tr.configured  # not lost, not reconnected
    assert reboots(row) == 0
    row.send(0x000, bytes([0x01, NODE]))  # the service tool's NMT start lifts it
    assert seen(row, "OPERATIONAL")
    assert row.cycle().health == "ok"


def test_a_quick_stop_by_another_master_is_held(row):
    """It had been re-enabled after three cycles (lost, reconnected), and the axis slewed."""
    row.cycle()
    row.send(0x600 + NODE, bytes([0x2B, 0x40, 0x60, 0x00, 0x02, 0x00, 0, 0]))  # controlword: quick stop
    held = row.fw.axes[0].target  # the quick stop's halt: where the axis stands
    for _ in range(6):
        rec = row.cycle()
        assert rec.health == "degraded" and "QUICK_STOP_ACTIVE" in rec.health_reason, rec
    assert row.node().sm.state == State402.QUICK_STOP_ACTIVE
    assert row.fw.axes[0].target == pytest.approx(held, abs=0.01)  # no set-point since
    assert row.tr.configured


def test_a_reset_of_the_nodes_communication_is_configured_again(row):
    """The node reset its communication (boot-up, 0x1016 back to "not monitored") with its
    uptime going on: it had been started again but never configured, its watchdog off."""
    row.cycle()
    assert row.fw.heartbeat_timeout == pytest.approx(65.0)
    row.send(0x000, bytes([0x82, NODE]))
    row.fw.heartbeat_timeout = 0.0  # what a reset of communication leaves
    rec = row.cycle()
    assert row.fw.heartbeat_timeout == pytest.approx(65.0)
    assert reboots(row) == 1 and rec.health == "ok", rec


def test_a_fault_only_the_402_layer_holds_is_a_fault_and_is_cleared(row):
    """A stall latched, then cleared on the drive's own port: the 402 layer stayed in FAULT
    and dropped every set-point, reported ok for 12 cycles."""
    row.cycle()
    row.fw.axes[0].jammed = True
    target = register("TARGET_ANGLE")
    row.fw.write(target.address(0), encode(target, 10.0))
    fault_code = register("FAULT_CODE")
    for _ in range(40):
        row.clock.sleep(1.0)
        time.sleep(0.02)
        if row.fw.read(fault_code.address(0), 1)[0]:
            break
    assert row.fw.read(fault_code.address(0), 1)[0] == Fault.STALL
    row.fw.axes[0].jammed = False
    command = register("COMMAND")
    row.fw.write(command.address(), encode(command, int(Command.CLEAR_FAULT)))  # cleared locally
    time.sleep(0.2)
    assert row.node().sm.state == State402.FAULT
    rec = row.cycle()
    assert rec.health == "degraded" and "fault" in rec.health_reason.lower(), rec
    time.sleep(0.2)
    rec = row.cycle()  # CLEAR_FAULT sent last cycle: a fault reset, enabled again
    assert row.node().sm.state == State402.OPERATION_ENABLED, rec
    assert row.fw.axes[0].target == pytest.approx(rec.targets_deg[0], abs=0.01)


def test_another_device_at_the_node_id_is_named(row):
    row.cycle()
    n = row.node()
    raw = n.object_raw
    n.object_raw = lambda i, s, snap=None: 0xBEEF if (i, s) == (0x2000, 0) else raw(i, s, snap)
    msgs = []
    for _ in range(3):
        rec = row.cycle()
        msgs.append(rec.error + rec.health_reason)
    assert any("identity changed (0x2000 = 0xbeef" in m for m in msgs), msgs


def test_a_firmware_latching_other_targets_is_named(row):
    """It acknowledged every set-point and latched it 30 deg further, without TARGET_CLAMPED:
    ok, every cycle."""
    row.cycle()
    n = row.node()
    write = n._reg_write_raw
    n._reg_write_raw = lambda name, raw: write(name, raw + 30000 if name == "TARGET_ANGLE" else raw)
    rec = row.cycle()
    assert rec.health == "degraded" and "another target latched" in rec.health_reason, rec
    assert rec.axis_modes == (Mode.AUTO.name,)


def test_a_row_on_a_drive_of_two_axes_is_refused_by_name():
    """A single-axis row given a dual-axis drive's id had been configured with the row's
    limits on the azimuth axis, refused by it every cycle with an exception code."""
    r = Row(axes=2)
    try:
        r.loop.run_until_complete(r.ctl.start())
        assert r.tr.health.state == Health.DEGRADED
        assert "drive has 2 axes, a single-axis tracker drives 1: wrong device_id?" in r.tr.health.reason
    finally:
        r.close()


def test_an_unexpected_error_at_start_up_stays_that_drives():
    """A library's exception in one drive's start-up had propagated out of the plant's start."""
    r = Row()

    async def broken() -> None:
        raise ValueError("non-hexadecimal number found in fromhex() arg at position 0")

    r.drive.connect = broken  # type: ignore[method-assign]
    try:
        r.loop.run_until_complete(r.ctl.start())
        assert r.tr.health.state == Health.DEGRADED
        assert r.tr.health.reason == "ValueError: non-hexadecimal number found in fromhex() arg at position 0"
    finally:
        r.close()
