"""The controller's CANopen backend against the emulated CiA 402 drive on the virtual bus."""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import math
import os
import time

import pytest

from controller.drives import DriveCommError, open_drive
from controller.drives.canopen import CanopenDrive, SharedNetwork
from controller.drives.links import CanopenLink
from firmware_protocol import Command, Fault, Mode, ProtocolError, Status
from hil.drive import DriveFirmware
from tests.hil.canopen.rig import emulated, one_axis, two_axes


def run(coro):
    return asyncio.run(coro)


def can(channel: str, **kw) -> CanopenLink:
    """A ``[[links]]`` table for the emulator's virtual bus."""
    return CanopenLink(name="can-1", interface="virtual", channel=channel, **kw)


async def settle(d, predicate, timeout=3.0):
    """Poll read_state until ``predicate(state)`` (the emulator sends TPDOs on change)."""
    deadline = time.monotonic() + timeout
    while True:
        st = await d.read_state()
        if predicate(st) or time.monotonic() > deadline:
            return st
        await asyncio.sleep(0.01)


def test_connect_targets_state_and_configuration(sim_clock):
    with emulated(axes=two_axes(), node_id=10, now=sim_clock.now) as (fw, _emu, ch):

        async def scenario():
            d = open_drive(can(ch), 10)
            assert isinstance(d, CanopenDrive)
            await d.connect()
            try:
                assert d.axis_count == 2
                await d.configure(
                    heartbeat_timeout_s=50, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 80]
                )
                assert fw.heartbeat_timeout == pytest.approx(50)
                assert fw.axes[1].p.soft_min == pytest.approx(5)
                assert fw.axes[1].p.stow_angle == pytest.approx(80)
                st = await d.exchange([150.0, 30.0])
                assert st.axes[0].target_deg == pytest.approx(150.0)  # state after the write
                assert fw.axes[1].target == pytest.approx(30.0)
                for _ in range(10):
                    await d.heartbeat()
                    sim_clock.sleep(5)
                st = await settle(d, lambda s: all(a.status & Status.AT_TARGET for a in s.axes))
                assert st.axes[0].actual_deg == pytest.approx(150.0, abs=0.03)
                assert st.axes[1].actual_deg == pytest.approx(30.0, abs=0.03)
                assert st.axes[1].mode == Mode.AUTO and st.axes[1].fault == Fault.NONE
                await d.write_targets([400.0, 30.0])  # clamped by the drive
                st = await settle(d, lambda s: s.axes[0].status & Status.TARGET_CLAMPED)
                assert st.axes[0].target_deg == pytest.approx(350.0)
                assert d.stats.errors == 0 and d.stats.transactions > 0
            finally:
                await d.close()

        run(scenario())


def test_heartbeat_loss_stows_and_resume_recovers(sim_clock):
    with emulated(axes=one_axis(), node_id=3, now=sim_clock.now) as (fw, _emu, ch):

        async def scenario():
            d = open_drive(can(ch), 3)
            await d.connect()
            try:
                await d.configure(heartbeat_timeout_s=2.0)
                await d.write_targets([20.0])
                sim_clock.sleep(3.0)  # no heartbeat
                st = await settle(d, lambda s: s.axes[0].mode == Mode.STOW)
                assert st.axes[0].mode == Mode.STOW
                assert st.axes[0].status & Status.COMM_LOST
                assert st.axes[0].status & Status.WATCHDOG_STOW
                await d.heartbeat()
                # the heartbeat clears COMM_LOST; whose stow it is stays in the TPDOs
                st = await settle(d, lambda s: not s.axes[0].status & Status.COMM_LOST)
                assert st.axes[0].mode == Mode.STOW and st.axes[0].status & Status.WATCHDOG_STOW
                await d.command(Command.RESUME)
                st = await settle(d, lambda s: s.axes[0].mode == Mode.AUTO)
                assert st.axes[0].mode == Mode.AUTO and not st.axes[0].status & Status.WATCHDOG_STOW
                await d.write_targets([5.0])
                assert fw.axes[0].target == pytest.approx(5.0)
            finally:
                await d.close()

        run(scenario())


def test_fault_is_reported_and_clear_fault_recovers():
    with emulated(axes=one_axis(stall_time=0.1), node_id=4) as (fw, _emu, ch):

        async def scenario():
            d = open_drive(can(ch), 4)
            await d.connect()
            try:
                fw.axes[0].jammed = True
                await d.write_targets([10.0])
                st = await settle(d, lambda s: s.faulted)
                assert st.faulted and st.axes[0].fault == Fault.STALL
                await d.write_targets([0.0])  # skipped: FAULT is in the state, no error
                fw.axes[0].jammed = False
                await d.command(Command.CLEAR_FAULT)
                st = await settle(d, lambda s: not s.faulted)
                assert not st.faulted
                await d.write_targets([2.0])
                assert fw.axes[0].target == pytest.approx(2.0)
            finally:
                await d.close()

        run(scenario())


def test_errors_are_clear_and_nothing_unsafe_is_sent():
    with emulated(axes=one_axis(), node_id=6) as (fw, emu, ch):

        async def scenario():
            ghost = open_drive(can(ch, timeout_s=0.05, retries=0), 40)
            with pytest.raises(DriveCommError, match="node 40"):
                await ghost.connect()
            d = open_drive(can(ch), 6)
            await d.connect()
            try:
                with pytest.raises(ProtocolError):
                    await d.write_targets([math.nan])
                with pytest.raises(ValueError):
                    await d.write_targets([1.0, 2.0])
                assert fw.axes[0].target == 0.0
                # Another master disables the axis: no automatic re-enable.
                d.axes[0].node.controlword = 0x07
                await asyncio.sleep(0.05)
                with pytest.raises(DriveCommError, match="not OPERATION ENABLED"):
                    await d.write_targets([3.0])
                assert fw.axes[0].target == 0.0
                emu.remove_drive(emu.drives[0])  # cable pulled
                await asyncio.sleep(0.05)
                d.stale_s = 0.2
                await asyncio.sleep(0.3)
                with pytest.raises(DriveCommError, match="TPDO|heartbeat"):
                    await d.read_state()
            finally:
                await d.close()

        run(scenario())


def test_many_drives_share_one_network():
    n = 24
    with emulated(axes=one_axis(), node_id=1) as (fw0, emu, ch):
        fws = [fw0] + [DriveFirmware(one_axis(), time.time, heartbeat_timeout=0) for _ in range(n - 1)]
        for i, f in enumerate(fws[1:], start=2):
            emu.add_drive(f, i)
        link = can(ch, pdo_mapping="eds")

        async def scenario():
            drives = [open_drive(link, i + 1) for i in range(n)]
            await asyncio.gather(*(d.connect() for d in drives))
            net = drives[0].network
            try:
                assert all(d.network is net for d in drives)  # one bus, one network
                states = await asyncio.gather(*(d.exchange([0.25 * k]) for k, d in enumerate(drives)))
                assert [s.axes[0].target_deg for s in states] == pytest.approx([0.25 * k for k in range(n)])
                with pytest.raises(DriveCommError, match="already in use"):
                    await open_drive(link, 1).connect()
                assert net.nodes[1] is drives[0].axes[0].node  # the failed one left it alone
                assert (await drives[0].read_state()).axes[0].target_deg == 0.0
            finally:
                await asyncio.gather(*(d.close() for d in drives))
            assert not net.nodes
            assert ("virtual", ch) not in SharedNetwork._open  # the last one closed it

        run(scenario())


def test_a_bus_only_the_simulator_provides_is_refused():
    from controller.drives import LinkSettingsError

    with pytest.raises(LinkSettingsError, match='channel = "hil"'):
        open_drive(CanopenLink(name="can-1"), 1)


def test_the_master_heartbeat_is_one_frame_per_round_of_drives():
    from tests.hil.canopen.rig import wait_for

    with emulated(axes=one_axis(), node_id=1) as (_fw, emu, ch):
        for i in range(2, 5):
            emu.add_drive(DriveFirmware(one_axis(), time.time, heartbeat_timeout=0), i)
        seen = []
        emu.network.subscribe(0x77F, lambda *frame: seen.append(frame))

        async def scenario():
            drives = [open_drive(can(ch, pdo_mapping="eds"), i) for i in range(1, 5)]
            await asyncio.gather(*(d.connect() for d in drives))
            try:
                before = sum(d.stats.transactions for d in drives)
                # Two rounds back to back, as two control cycles of a fast simulated clock:
                # every round reaches the bus (four drives, one frame each round).
                for _ in range(2):
                    await asyncio.gather(*(d.heartbeat() for d in drives))
                    await asyncio.sleep(0)
                assert sum(d.stats.transactions for d in drives) - before == 2
            finally:
                await asyncio.gather(*(d.close() for d in drives))

        run(scenario())
        assert wait_for(lambda: len(seen) >= 2)
        assert all(frame[1] == bytearray(b"\x05") for frame in seen)


def test_connecting_again_starts_afresh():
    with emulated(axes=one_axis(), node_id=9) as (fw, _emu, ch):

        async def scenario():
            d = open_drive(can(ch), 9)
            await d.connect()
            try:
                await d.connect()  # as the loop does after a failed configuration
                assert d.axis_count == 1
                await d.write_targets([4.0])
                assert fw.axes[0].target == pytest.approx(4.0)
            finally:
                await d.close()

        run(scenario())


def test_the_configuration_is_read_back():
    """An audit's case: SDO downloads are confirmed by the node, not by its firmware; a
    firmware that kept its watchdog off and its own stow angle was driven as configured."""
    from firmware_protocol import register

    with emulated(axes=two_axes(), node_id=10) as (fw, _emu, ch):

        async def configure(d):
            await d.configure(heartbeat_timeout_s=50, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 80])

        async def scenario():
            d = open_drive(can(ch), 10)
            await d.connect()
            try:
                await configure(d)
                got = await d.read_configuration()
                assert got.heartbeat_timeout_s == pytest.approx(50) and got.producers == (127, 127)
                assert got.soft_limits == (pytest.approx((10, 350)), pytest.approx((5, 85)))
                assert got.stow_angles == pytest.approx((180, 80))
                assert got.describe() == (
                    "watchdog 50 s on node 127; limits [10, 350] / [5, 85] deg; stow 180 / 80 deg; speed 10 / 10 deg/s"
                )
                # now a firmware that acknowledges and ignores the watchdog and axis 1's stow angle
                ignored = {register("HEARTBEAT_TIMEOUT").address(), register("STOW_ANGLE").address(1)}
                write = fw.write
                fw.write = lambda address, words: None if address in ignored else write(address, words)
                with pytest.raises(DriveCommError) as e:
                    await d.configure(
                        heartbeat_timeout_s=30, soft_limits=[(10, 350), (5, 85)], stow_angles=[180, 60]
                    )
                return str(e.value)
            finally:
                await d.close()

        msg = run(scenario())
    assert "configuration not taken: watchdog reads" in msg and "30 s written" in msg, msg
    assert "axis 1 stow angle reads 80, 60 written" in msg, msg
    assert "axis 0" not in msg, msg


def test_a_malformed_slcan_line_is_dropped_and_the_drive_goes_on():
    """An audit's case: one garbled line on the USB-CAN adapter's serial link stopped
    python-can's notifier thread for good, every later cycle "ValueError: non-hexadecimal
    number" until the controller restarted."""
    from hil.canopen.slcan import open_slcan_pty

    with emulated(axes=one_axis(), node_id=8) as (_fw, _emu, ch):
        link, adapter = open_slcan_pty(ch)
        try:

            async def scenario():
                d = open_drive(CanopenLink(name="usb", interface="slcan", channel=link.path), 8)
                await d.connect()
                try:
                    adapter._write(b"t1A18zz\r")  # a line that is not hex
                    await asyncio.sleep(0.3)
                    await d.write_targets([4.0])
                    return await settle(d, lambda s: s.axes[0].target_deg == pytest.approx(4.0)), d
                finally:
                    await d.close()

            st, d = run(scenario())
        finally:
            adapter.stop()
            adapter.bus.shutdown()
            link.close()
    assert st.axes[0].target_deg == pytest.approx(4.0)


@contextlib.contextmanager
def another_party(ch: str):
    """``send(cob_id, data)``: frames on the bus from someone else (a raw python-can handle)."""
    import can as python_can

    bus = python_can.Bus(interface="virtual", channel=ch)
    try:
        yield lambda cob_id, data: bus.send(
            python_can.Message(arbitration_id=cob_id, data=data, is_extended_id=False)
        )
    finally:
        bus.shutdown()


def test_a_tpdo_of_the_wrong_length_is_dropped_whole(caplog):
    """An audit's case: TPDO1 cut to 4 bytes updated the statusword, left the position
    stale, and logged an error ten times a second naming no node."""
    with emulated(axes=one_axis(), node_id=9) as (_fw, _emu, ch), another_party(ch) as send:

        async def scenario():
            d = open_drive(can(ch), 9)
            await d.connect()
            try:
                before = d.axes[0].node.tpdo_values.get(0x6041)
                for _ in range(5):
                    send(0x189, b"\xff\xff\x01\x02")
                await asyncio.sleep(0.2)
                return (
                    before,
                    d.axes[0].node.tpdo_values.get(0x6041),
                    d.axes[0].bad_length,
                    await d.read_state(),
                )
            finally:
                await d.close()

        before, after, dropped, st = run(scenario())
    assert dropped == 5 and after == before  # nothing of the short frames was taken
    assert st.axes[0].actual_deg == pytest.approx(0.0, abs=0.01)
    warned = [
        r for r in caplog.records if "TPDO1 from node 9 has 4 bytes, its layout needs 6" in r.getMessage()
    ]
    assert len(warned) == 1
    assert not [r for r in caplog.records if r.name.startswith("canopen") and r.levelname == "ERROR"]


def test_an_emcy_is_logged_with_its_node(caplog):
    """A vendor EMCY (0xFF42, error register 0x81) had been neither logged nor used."""
    with emulated(axes=one_axis(), node_id=12) as (_fw, _emu, ch), another_party(ch) as send:

        async def scenario():
            d = open_drive(can(ch), 12)
            await d.connect()
            try:
                send(0x80 + 12, bytes([0x42, 0xFF, 0x81, 0, 0, 0, 0, 0]))
                send(0x80 + 12, bytes([0x42, 0xFF, 0x81]))  # a short one: dropped, named
                await asyncio.sleep(0.2)
            finally:
                await d.close()

        run(scenario())
    assert any("EMCY from node 12: 0xFF42 (error register 0x81)" in r.getMessage() for r in caplog.records)
    assert any("EMCY from node 12 has 3 bytes, its layout needs 8" in r.getMessage() for r in caplog.records)
    assert not [r for r in caplog.records if r.name.startswith("canopen") and r.levelname == "ERROR"]


def test_a_node_that_does_not_start_is_named():
    """A node that stays PRE-OPERATIONAL after NMT start (it answers SDO) had been reported
    as "Timeout when trying to change state", then "probed, no answer"."""
    with emulated(axes=one_axis(), node_id=13) as (_fw, emu, ch):
        node = emu.drives[0].nodes[0].node
        node.network.unsubscribe(0, node.nmt.on_command)  # deaf to NMT commands
        d = open_drive(can(ch, timeout_s=0.2, retries=0), 13)
        try:
            with pytest.raises(DriveCommError) as e:
                run(d.connect())
        finally:
            node.network.subscribe(0, node.nmt.on_command)  # the emulator's stop takes it off
    assert (
        "node 13 sent no TPDO within 0.4 s of NMT start (it answers SDO: does it stay PRE-OPERATIONAL?)"
        in str(e.value)
    )


def test_a_bus_whose_reception_died_is_opened_afresh():
    """A network whose receive thread had stopped (its adapter or pty gone) was handed to
    the next drive on the same channel, which then failed at its first SDO: the full
    suite's doc example once met a dead network left on a pty name the OS had reused."""
    from tests.hil.canopen.rig import channel

    ch = channel()
    first = SharedNetwork.acquire("virtual", ch, {})
    try:
        first.network.notifier.exception = OSError("device disconnected")  # what the thread leaves
        second = SharedNetwork.acquire("virtual", ch, {})
        try:
            assert second is not first and not second.dead
            assert SharedNetwork.acquire("virtual", ch, {}) is second
            second.release()
        finally:
            second.release()
    finally:
        first.release()
    assert ("virtual", ch) not in SharedNetwork._open


def _flock(path: str) -> int | None:
    """Another program's exclusive hold on ``path`` (pyserial's ``exclusive``): its file
    descriptor, or None when someone holds the port already."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    return fd


def test_an_slcan_adapter_is_held_exclusively():
    """An audit's case: ``heliotrack check`` beside a running ``run`` opened the same slcan
    adapter (python-can opens it without a lock); each took the other's bytes, ``run``'s
    reception stopped with a traceback and its CAN row was lost for a minute, while
    ``check`` called the drive ok.  The adapter is now held as a Modbus port is: a second
    opener is told it is in use, and a network opened afresh after a dead one still gets it."""
    from hil.canopen.slcan import open_slcan_pty

    with emulated(axes=one_axis(), node_id=8) as (_fw, _emu, ch):
        link, adapter = open_slcan_pty(ch)
        try:
            usb = CanopenLink(name="usb", interface="slcan", channel=link.path)

            async def scenario():
                d = open_drive(usb, 8)
                await d.connect()
                try:
                    assert _flock(link.path) is None  # held while the drive is open
                    shared = SharedNetwork._open[("slcan", link.path)]
                    # dead as a real one is: its receive thread ended with an error (a thread
                    # left reading would share the pty with the fresh network's and fail on
                    # the bytes it took: "multiple access on port", a warning in the suite)
                    shared.network.notifier.stop(1.0)
                    shared.network.notifier.exception = OSError("device disconnected")
                    fresh = await asyncio.to_thread(SharedNetwork.acquire, "slcan", link.path, d.bus_kwargs)
                    assert fresh is not shared  # it could take the port over
                    fresh.release()
                finally:
                    await d.close()
                # the other way round: a port another program holds is refused, saying so
                other = _flock(link.path)
                assert other is not None  # released with the last drive
                try:
                    d = open_drive(usb, 8)
                    with pytest.raises(DriveCommError, match=f"{link.path}: in use by another program"):
                        await d.connect()
                    await d.close()
                finally:
                    os.close(other)

            run(scenario())
        finally:
            adapter.stop()
            adapter.bus.shutdown()
            link.close()


def _held(path: str) -> list[str]:
    """This process's file descriptors on ``path`` (also once the device is gone)."""
    out = []
    for fd in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):
            if os.readlink(f"/proc/self/fd/{fd}") in (path, f"{path} (deleted)"):
                out.append(fd)
    return out


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # python-can's reader
@pytest.mark.parametrize("reader", ["reading", "stopped"])
def test_an_unplugged_slcan_adapter_is_dead_and_let_go(reader):
    """A walk of docs/deploy.md: with the USB-CAN adapter gone (its emulator killed),
    python-can's slcan shutdown wrote its close command first, which raised, and never
    closed the port: the controller kept the vanished device open, so the adapter plugged
    back came up under another name (/dev/ttyACM1 for /dev/ttyACM0; here another pty) and
    the row stayed lost until a restart.  And the network is dead at once, not only once
    its receive thread has read the hang-up ("stopped": a thread that has not read since),
    so a new adapter under the old one's name gets a fresh network."""
    from hil.canopen.slcan import open_slcan_pty

    with emulated(axes=one_axis(), node_id=8) as (_fw, _emu, ch):
        link, adapter = open_slcan_pty(ch)
        path = link.path

        async def scenario():
            d = open_drive(CanopenLink(name="usb", interface="slcan", channel=path), 8)
            await d.connect()
            shared = SharedNetwork._open[("slcan", path)]
            assert not shared.dead
            if reader == "stopped":
                shared.network.notifier.stop()
            adapter.stop()
            adapter.bus.shutdown()
            link.close()  # unplugged
            if reader == "stopped":
                assert shared.network.notifier.exception is None and shared.dead
            for _ in range(50):
                if shared.dead:
                    break
                await asyncio.sleep(0.05)
            assert shared.dead
            await d.close()  # as the loop closes a lost link

        run(scenario())
    assert _held(path) == []
