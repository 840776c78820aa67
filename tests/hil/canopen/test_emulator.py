"""The emulated drive as CANopen slaves on the virtual bus, driven by canopen's BaseNode402."""

from __future__ import annotations

import time

import pytest
from canopen.sdo import SdoAbortedError

from firmware_protocol import Fault, Mode, Status
from firmware_protocol.canopen import FAULT_ERROR_CODES, MASTER_NODE_ID, Statusword
from hil.errors import HilError

from .rig import emulated, master, node402, one_axis, two_axes, wait_for

ACK = Statusword.SET_POINT_ACK


def _enable(node):
    node.op_mode = "PROFILED POSITION"
    node.state = "OPERATION ENABLED"
    assert node.state == "OPERATION ENABLED"


def _set_point(node, deg: float, cw: int = 0x3F) -> bool:
    node.rpdo[1]["Target position"].raw = round(deg * 1000)
    node.controlword = cw
    acked = wait_for(lambda: node.statusword & ACK, 1.0 if cw & 0x08 else 0.2)
    node.controlword = cw & ~0x30
    return bool(acked)


def test_402_state_machine_and_profile_position_reach_the_target():
    with emulated() as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        assert wait_for(lambda: node.state == "SWITCH ON DISABLED")
        assert node.sdo[0x1000].raw & 0xFFFF == 0x192
        _enable(node)
        assert _set_point(node, 3.0)
        assert wait_for(lambda: not node.statusword & ACK)  # handshake completes
        assert wait_for(
            lambda: (
                node.statusword & Statusword.TARGET_REACHED and abs(node.tpdo_values[0x6064] - 3000) <= 20
            ),
            5.0,
        )
        assert fw.true_angles()[0] == pytest.approx(3.0, abs=0.05)
        assert node.sdo[0x2100].raw == 3000  # effective target mirror


def test_set_point_is_not_taken_unless_operation_enabled():
    with emulated() as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        node.state = "SWITCHED ON"
        assert not _set_point(node, 10.0, cw=0x37)  # new set-point, operation disabled
        assert node.state == "SWITCHED ON"
        assert fw.axes[0].target == 0.0
        _enable(node)
        assert not _set_point(node, 10.0, cw=0x13F)  # halt bit: set-points are not taken
        assert fw.axes[0].target == 0.0
        node.sdo[0x6060].raw = 0  # no mode: no profile position
        assert not _set_point(node, 10.0)
        assert fw.axes[0].target == 0.0
        node.sdo[0x6060].raw = 1
        assert _set_point(node, 10.0)


def test_leaving_operation_enabled_halts_the_axis():
    with emulated(axes=one_axis(max_speed=2.0, accel=20.0)) as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        assert _set_point(node, 50.0)
        assert wait_for(lambda: fw.axes[0].velocity > 1.0)
        node.state = "SWITCHED ON"  # disable operation
        assert fw.axes[0].target < 10.0  # stops where it is, not at 50
        assert wait_for(lambda: fw.axes[0].velocity == 0.0)


def test_a_halt_a_hair_past_the_limit_holds_inside_it_and_is_no_masters_command():
    """The drive's own halt is not a target from a master: the soak's audit counted one
    (an axis 0.01 deg under its soft minimum, inside the deadband) as written off limits."""
    with emulated(axes=one_axis(soft_min=0.0, initial_angle=0.0)) as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        fw.axes[0].encoder_offset = -0.01  # the encoder reads a hair under the limit
        assert wait_for(lambda: fw.axes[0].encoder < 0.0)
        node.state = "SWITCHED ON"  # leaving OPERATION ENABLED halts the axis where it is
        assert fw.axes[0].target == pytest.approx(0.0)  # held inside its limits
        assert fw.out_of_limit_writes == 0 and fw.target_writes == 0


def test_out_of_limit_set_point_is_clamped_and_flagged():
    with emulated() as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        assert _set_point(node, 500.0)
        assert fw.axes[0].target == 60.0
        assert wait_for(lambda: node.statusword & Statusword.INTERNAL_LIMIT)
        assert Status(node.sdo[0x2105].raw) & Status.TARGET_CLAMPED


def test_fault_reaction_emcy_and_fault_reset():
    with emulated(axes=one_axis(stall_time=0.2)) as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        fw.axes[0].jammed = True
        assert _set_point(node, 5.0)
        assert wait_for(lambda: node.state == "FAULT", 5.0)
        assert node.sdo[0x603F].raw == FAULT_ERROR_CODES[Fault.STALL]
        assert node.sdo[0x1001].raw & 1
        assert wait_for(lambda: any(e.code == FAULT_ERROR_CODES[Fault.STALL] for e in node.emcy.log))
        with pytest.raises(RuntimeError):  # cause still present: stays in FAULT
            node.state = "OPERATION ENABLED"
        assert node.state == "FAULT"
        fw.axes[0].jammed = False
        node.controlword = 0x00
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        assert node.sdo[0x603F].raw == 0


def test_a_fault_reset_on_one_node_takes_every_cleared_axis_out_of_fault():
    """CLEAR_FAULT is the drive's: a reset on node 10 had cleared axis 1's fault too, but
    left node 11 in 402 FAULT with no fault code, for good."""
    with emulated(axes=two_axes(), node_id=10) as (fw, _emu, ch), master(ch) as net:
        nodes = [node402(net, 10), node402(net, 11)]
        for n in nodes:
            _enable(n)
        for ax in fw.axes:
            ax.p.stall_time = 0.2
            ax.jammed = True
        assert _set_point(nodes[0], 170.0) and _set_point(nodes[1], 80.0)
        assert wait_for(lambda: all(n.state == "FAULT" for n in nodes), 5.0)
        for ax in fw.axes:
            ax.jammed = False
        nodes[0].controlword = 0x00
        nodes[0].controlword = 0x80  # fault reset edge on node 10 only
        assert wait_for(lambda: nodes[0].state == "SWITCH ON DISABLED")
        assert wait_for(lambda: nodes[1].state == "SWITCH ON DISABLED"), nodes[1].statusword
        assert nodes[1].sdo[0x603F].raw == 0


def test_heartbeat_consumer_stows_on_loss(sim_clock):
    with emulated(now=sim_clock.now) as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        node.sdo[0x1016][1].raw = (MASTER_NODE_ID << 16) | 1500
        assert fw.heartbeat_timeout == pytest.approx(1.5)
        assert node.sdo[0x1016][1].raw == (MASTER_NODE_ID << 16) | 1500
        assert _set_point(node, 20.0)
        for _ in range(5):  # alive: heartbeats keep it tracking
            net.send_message(0x700 + MASTER_NODE_ID, b"\x05")
            time.sleep(0.02)
            sim_clock.sleep(1.0)
        assert fw.modes[0] == Mode.AUTO
        sim_clock.sleep(2.0)  # silence longer than 1.5 s
        assert wait_for(lambda: node.tpdo_values.get(0x2107) == Mode.STOW)
        assert Status(node.tpdo_values[0x2105]) & Status.COMM_LOST
        assert node.statusword & Statusword.WARNING
        assert fw.axes[0].target == 0.0  # the stow angle


def test_sync_triggers_synchronous_tpdos():
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        node.nmt.state = "PRE-OPERATIONAL"
        node.tpdo[1].trans_type = 1
        node.tpdo[1].save()
        node.nmt.state = "OPERATIONAL"
        time.sleep(0.1)
        before = node.tpdo[1].timestamp
        time.sleep(0.15)
        assert node.tpdo[1].timestamp == before  # no SYNC, no TPDO1
        net.sync.transmit()
        assert wait_for(lambda: node.tpdo[1].timestamp != before)


def test_bad_wire_data_is_refused():
    with emulated() as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        with pytest.raises(SdoAbortedError):
            node.sdo[0x6060].raw = 3  # profile velocity: not supported
        with pytest.raises(SdoAbortedError):
            node.sdo[0x607D][1].raw = -100_000  # beyond the hard limit
        with pytest.raises(SdoAbortedError):
            node.sdo[0x6064].raw = 5  # read-only
        with pytest.raises(SdoAbortedError):
            node.sdo[0x2107].raw = 9  # not a Mode
        # A too-short RPDO1 is not processed: no set-point, an EMCY 0x8210 instead.
        net.send_message(0x205, b"\x3f\x00\x10")
        assert wait_for(lambda: any(e.code == 0x8210 for e in node.emcy.log))
        assert fw.axes[0].target == 0.0
        net.send_message(0x000, b"\x01")  # malformed NMT command: dropped
        assert _set_point(node, 1.0)  # the bus still works


def test_nmt_reset_reboots_the_node():
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        states = []
        node.nmt.add_heartbeat_callback(states.append)
        node.nmt.send_command(0x81)
        assert wait_for(lambda: 0 in states and states[-1] == 127)  # boot-up, PRE-OP
        assert node.sdo[0x6041].raw & 0x4F == 0x40  # SWITCH ON DISABLED


def test_two_axes_are_two_nodes_of_one_drive():
    with emulated(axes=two_axes(), node_id=20) as (fw, emu, ch), master(ch) as net:
        a0, a1 = node402(net, 20), node402(net, 21)
        assert (a0.sdo[0x2020].raw, a1.sdo[0x2020].raw) == (0, 1)
        assert a0.sdo[0x2002].raw == a1.sdo[0x2002].raw == 2
        _enable(a1)
        assert _set_point(a1, 80.0)
        assert fw.axes[1].target == 80.0 and fw.axes[0].target == 180.0
        with pytest.raises(HilError):
            emu.add_drive(fw, 21)  # node 21 is taken


def test_many_drives_share_one_virtual_bus():
    from hil.drive import DriveFirmware

    with emulated(node_id=1) as (_fw, emu, ch), master(ch) as net:
        fws = [DriveFirmware(one_axis(), time.time, heartbeat_timeout=0) for _ in range(12)]
        for i, f in enumerate(fws):
            emu.add_drive(f, 2 + i)
        nodes = [node402(net, 2 + i) for i in range(12)]
        for n in nodes:
            _enable(n)
            assert _set_point(n, 0.5)
        assert all(f.axes[0].target == 0.5 for f in fws)


def test_the_quick_stop_option_code_says_what_a_quick_stop_does():
    """0x605A had been missing (abort 0x06020000): a master could not tell that a quick stop
    stays in QUICK STOP ACTIVE (option 6) rather than ending in SWITCH ON DISABLED."""
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        assert node.sdo[0x605A].raw == 6
        node.controlword = 0x02  # quick stop
        assert wait_for(lambda: node.state == "QUICK STOP ACTIVE")
        node.controlword = 0x0F  # enable operation: back, as option 6 allows
        assert wait_for(lambda: node.state == "OPERATION ENABLED")


def test_a_sub_index_the_object_does_not_have_is_refused():
    """canopen's dictionary had made up 0x607D:3 and 0x1016:2 and taken writes to them; a
    real node aborts with 0x06090011."""
    with emulated() as (_fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        for index, sub in ((0x607D, 3), (0x1016, 2)):
            with pytest.raises(SdoAbortedError) as e:
                node.sdo.download(index, sub, b"\x01\x00\x00\x00")
            assert e.value.code == 0x06090011
        with pytest.raises(SdoAbortedError) as e:
            node.sdo.upload(0x2000, 7)
        assert e.value.code == 0x06090011
        assert node.sdo.upload(0x607D, 2)  # what the object has still answers


def test_clearing_the_halt_bit_resumes_the_motion():
    """CiA 402: halt (bit 8) stops the axis, clearing it goes on to the target; the
    emulator had forgotten the target."""
    with emulated() as (fw, _emu, ch), master(ch) as net:
        node = node402(net, 5)
        _enable(node)
        assert _set_point(node, 30.0)
        node.controlword = 0x010F  # halt
        assert wait_for(lambda: fw.axes[0].target != 30.0)
        node.controlword = 0x000F  # halt cleared
        assert wait_for(lambda: fw.axes[0].target == pytest.approx(30.0))
