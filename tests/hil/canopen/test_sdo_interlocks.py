"""The emulated drive's interlocks seen from a CANopen master (issue 13): SDO writes of the
soft limits (0x607D), of the stow angle mirror (0x210D), of the consumer heartbeat time
(0x1016) and of the mode (0x2107) obey the rules the Modbus firmware enforces, because they
go through the same :class:`hil.drive.DriveFirmware`, and a refusal is an SDO abort:
0x06090030 (value range exceeded) for a value that can never be right, 0x08000022 (not in
the present device state) for one the drive's state forbids."""

from __future__ import annotations

import time

import canopen
import pytest
from canopen.sdo import SdoAbortedError

from firmware_protocol import Mode, Status
from firmware_protocol.canopen import MASTER_NODE_ID
from hil.canopen import object_dictionary

from .rig import emulated, master, one_axis, two_axes, wait_for

VALUE_RANGE = 0x06090030
STATE = 0x08000022
LIMITS = 0x607D
STOW_MIRROR = 0x210D
MODE = 0x2107
COMMAND = 0x2008


def sdo_node(net: canopen.Network, node_id: int) -> canopen.RemoteNode:
    node = canopen.RemoteNode(node_id, object_dictionary(node_id))
    net.add_node(node)
    return node


def aborted(write) -> int:
    """The abort code an SDO write gets (fails the test if it is accepted)."""
    with pytest.raises(SdoAbortedError) as e:
        write()
    return e.value.code


def test_soft_limits_stay_in_order_around_the_stow_angle_and_inside_the_hard_limits():
    # one axis: soft [-60, 60], hard [-65, 65], stow 0
    with emulated(heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 5)
        lo, hi = node.sdo[LIMITS][1], node.sdo[LIMITS][2]
        assert aborted(lambda: setattr(hi, "raw", -10_000)) == VALUE_RANGE  # stow 0 left outside
        assert aborted(lambda: setattr(lo, "raw", 10_000)) == VALUE_RANGE  # likewise
        assert aborted(lambda: setattr(lo, "raw", 61_000)) == VALUE_RANGE  # inverted
        assert aborted(lambda: setattr(hi, "raw", 70_000)) == VALUE_RANGE  # past the hard limit
        assert (fw.axes[0].p.soft_min, fw.axes[0].p.soft_max) == (-60.0, 60.0)
        hi.raw = 50_000  # narrower, still around the stow angle: accepted
        assert fw.axes[0].p.soft_max == pytest.approx(50.0)
        assert node.sdo[LIMITS][2].raw == 50_000


def test_a_stow_angle_outside_the_soft_limits_is_aborted():
    with emulated(heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 5)
        assert aborted(lambda: setattr(node.sdo[STOW_MIRROR], "raw", 6_200)) == VALUE_RANGE  # 62 deg
        assert aborted(lambda: setattr(node.sdo[STOW_MIRROR], "raw", -32_000)) == VALUE_RANGE
        assert fw.axes[0].p.stow_angle == 0.0
        node.sdo[STOW_MIRROR].raw = 2_500
        assert fw.axes[0].p.stow_angle == pytest.approx(25.0)


@pytest.mark.parametrize(
    "value",
    [
        (MASTER_NODE_ID << 16) | 0,  # time 0 from the usual master
        (0x10 << 16) | 0,  # ... or from any other
        (0x00 << 16) | 1000,  # node id 0: CiA 301 "not monitored", the watchdog off too
    ],
)
def test_the_watchdog_cannot_be_switched_off_outside_maintenance(value):
    with emulated(axes=two_axes(), node_id=20, heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        a0, a1 = sdo_node(net, 20), sdo_node(net, 21)
        for node in (a0, a1):
            assert aborted(lambda n=node: setattr(n.sdo[0x1016][1], "raw", value)) == STATE
        assert fw.heartbeat_timeout == 10.0
        assert a0.sdo[0x1016][1].raw == (MASTER_NODE_ID << 16) | 10_000
        a0.sdo[MODE].raw = int(Mode.MAINTENANCE)
        assert aborted(lambda: setattr(a0.sdo[0x1016][1], "raw", value)) == STATE  # axis 1 still AUTO
        a1.sdo[MODE].raw = int(Mode.MAINTENANCE)
        a0.sdo[0x1016][1].raw = value  # commissioning, every axis in MAINTENANCE: allowed
        assert fw.heartbeat_timeout == 0.0


def test_leaving_maintenance_needs_the_watchdog_on():
    with emulated(heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 5)
        node.sdo[MODE].raw = int(Mode.MAINTENANCE)
        node.sdo[0x1016][1].raw = MASTER_NODE_ID << 16  # watchdog off for commissioning
        assert aborted(lambda: setattr(node.sdo[MODE], "raw", int(Mode.AUTO))) == STATE
        assert fw.modes[0] == Mode.MAINTENANCE
        node.sdo[0x1016][1].raw = (MASTER_NODE_ID << 16) | 5000
        node.sdo[MODE].raw = int(Mode.AUTO)
        assert fw.modes[0] == Mode.AUTO and fw.heartbeat_timeout == 5.0


@pytest.mark.parametrize(
    "value",
    [
        (20 << 16) | 1000,  # the drive's own axis 0 node
        (21 << 16) | 1000,  # its axis 1 node
        (0x80 << 16) | 1000,  # not a node id
        (1 << 24) | (MASTER_NODE_ID << 16) | 1000,  # reserved bits set
    ],
)
def test_a_drive_watches_a_master_not_itself(value):
    with emulated(axes=two_axes(), node_id=20, heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 20)
        assert aborted(lambda: setattr(node.sdo[0x1016][1], "raw", value)) == VALUE_RANGE
        assert fw.heartbeat_timeout == 10.0
        assert node.sdo[0x1016][1].raw == (MASTER_NODE_ID << 16) | 10_000


def test_the_consumer_heartbeat_belongs_to_the_drive_not_to_one_axis_node(sim_clock):
    """0x1016 written on axis 0 sets the producer of both axis nodes: a heartbeat of the old
    producer must no longer feed the watchdog through axis 1."""
    axes = two_axes()
    with emulated(axes=axes, node_id=20, now=sim_clock.now, heartbeat_timeout=10.0) as (fw, _emu, ch):
        with master(ch) as net:
            a0, a1 = sdo_node(net, 20), sdo_node(net, 21)
            new = (0x10 << 16) | 1500
            a0.sdo[0x1016][1].raw = new
            assert a1.sdo[0x1016][1].raw == new
            assert fw.heartbeat_timeout == pytest.approx(1.5)
            for _ in range(4):  # the new producer keeps the drive alive
                net.send_message(0x710, b"\x05")
                time.sleep(0.02)
                sim_clock.sleep(1.0)
            assert not fw.comm_lost
            for _ in range(4):  # the old one does not
                net.send_message(0x700 + MASTER_NODE_ID, b"\x05")
                time.sleep(0.02)
                sim_clock.sleep(1.0)
            fw.update()
            assert fw.comm_lost and fw.modes == [Mode.STOW, Mode.STOW]


def test_a_mode_write_cannot_leave_stow_without_resume(sim_clock):
    with emulated(now=sim_clock.now, heartbeat_timeout=10.0) as (fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 5)
        node.sdo[COMMAND].raw = 1  # STOW
        assert fw.modes[0] == Mode.STOW
        for mode in (Mode.AUTO, Mode.MANUAL):
            assert aborted(lambda m=mode: setattr(node.sdo[MODE], "raw", int(m))) == STATE
        assert aborted(lambda: setattr(node.sdo[MODE], "raw", 9)) == VALUE_RANGE  # not a mode
        assert fw.modes[0] == Mode.STOW
        sim_clock.sleep(11.0)  # and after a watchdog stow, not even out of MAINTENANCE
        assert Status(node.sdo[0x2105].raw) & Status.COMM_LOST
        node.sdo[MODE].raw = int(Mode.MAINTENANCE)
        assert aborted(lambda: setattr(node.sdo[MODE], "raw", int(Mode.AUTO))) == STATE
        net.send_message(0x700 + MASTER_NODE_ID, b"\x05")  # the master is back ...
        assert wait_for(lambda: not fw.comm_lost)
        node.sdo[MODE].raw = int(Mode.STOW)
        node.sdo[COMMAND].raw = 2  # ... and RESUME is the way out
        assert fw.modes[0] == Mode.AUTO


def test_refused_writes_leave_the_data_store_alone():
    """A refused SDO write is not stored either: a read gives the firmware's value."""
    with emulated(axes=one_axis(), heartbeat_timeout=10.0) as (_fw, _emu, ch), master(ch) as net:
        node = sdo_node(net, 5)
        aborted(lambda: setattr(node.sdo[0x1016][1], "raw", MASTER_NODE_ID << 16))
        assert node.sdo[0x1016][1].raw == (MASTER_NODE_ID << 16) | 10_000
        aborted(lambda: setattr(node.sdo[STOW_MIRROR], "raw", 9_000))
        assert node.sdo[STOW_MIRROR].raw == 0
