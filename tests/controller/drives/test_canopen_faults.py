"""What CAN faults revealed in the CANopen drive link: a node that rebooted is started again
by the link, a state is never read from TPDOs older than a failure, a fault reset that the
fault survives is the drive's state and not a link error.  Faults are injected in the
emulator's bus (frames lost, bus-off) and in the emulated drive."""

import asyncio
import time
import uuid

import can
import pytest

from controller.drives import DriveCommError, open_drive
from controller.drives.base import LATENCY_WINDOW, LinkStats
from controller.drives.canopen import CanopenDrive
from controller.drives.links import CanopenLink
from controller.drives.retry import RetryPolicy
from firmware_protocol import Command, Fault, Mode, Status, register
from hil.canopen import CanopenNetworkEmulator
from hil.canopen.faulty_bus import CanFaults, FaultyBus
from hil.drive import DriveFirmware
from tests.hil.canopen.rig import one_axis


def run(coro):
    return asyncio.run(coro)


class FaultyCan:
    """A drive on a virtual bus whose emulator side loses what ``faults`` says."""

    def __init__(self, node_id: int = 5, heartbeat_timeout: float = 0.0, **axis):
        self.channel = f"ht-test-{uuid.uuid4().hex[:8]}"
        self.faults = CanFaults()
        bus = FaultyBus(can.Bus(interface="virtual", channel=self.channel), self.faults)
        self.emu = CanopenNetworkEmulator(self.channel, bus=bus, period_s=0.01).start()
        self.node_id = node_id
        self.fw = DriveFirmware(one_axis(**axis), time.time, heartbeat_timeout=heartbeat_timeout)
        self.emu.add_drive(self.fw, node_id)

    def link(self, **kw) -> CanopenLink:
        return CanopenLink(name="can-1", interface="virtual", channel=self.channel, **kw)

    def reboot(self) -> DriveFirmware:
        """The drive's emulator goes away and comes back with fresh firmware."""
        self.emu.remove_drive(self.emu.drives[0])
        self.fw = DriveFirmware(one_axis(), time.time, heartbeat_timeout=0.0)
        self.emu.add_drive(self.fw, self.node_id)
        return self.fw

    def close(self) -> None:
        self.emu.stop()


@pytest.fixture
def faulty_can():
    rig = FaultyCan()
    yield rig
    rig.close()


async def eventually(fn, timeout: float = 3.0):
    """``await fn()`` until it stops raising DriveCommError (the link's own recovery)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return await fn()
        except DriveCommError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)


def test_a_node_that_rebooted_is_started_again_by_the_link(faulty_can):
    async def scenario():
        d = open_drive(faulty_can.link(timeout_s=0.3), 5)
        await d.connect()
        try:
            await d.exchange([10.0])
            fresh = faulty_can.reboot()
            await asyncio.sleep(1.2)  # its boot-up and heartbeat (PRE-OPERATIONAL) arrive
            st = await eventually(lambda: d.exchange([12.0]))  # no connect() by the caller
            assert st.axes[0].mode == Mode.AUTO
            assert fresh.axes[0].target == pytest.approx(12.0)
            await d.connect()  # connecting again to an OPERATIONAL node: all TPDOs come at once
            assert (await d.read_state()).axes[0].target_deg == pytest.approx(12.0)
        finally:
            await d.close()

    run(scenario())


def test_after_a_failure_the_state_comes_from_tpdos_sent_since(faulty_can):
    async def scenario():
        d = open_drive(faulty_can.link(timeout_s=0.2, retries=0), 5)
        await d.connect()
        try:
            await d.exchange([0.0])
            faulty_can.faults.state = "bus_off"
            with pytest.raises(DriveCommError):
                await d.identify()
            faulty_can.fw.write(register("COMMAND").address(), [int(Command.STOW)])  # unheard
            faulty_can.faults.state = None
            st = await d.read_state()  # not the AUTO of the TPDOs held from before
            assert st.axes[0].mode == Mode.STOW
        finally:
            await d.close()

    run(scenario())


def test_a_fault_reset_the_fault_survives_is_the_drives_state_not_an_error():
    rig = FaultyCan(stall_time=0.1)
    try:

        async def scenario():
            d = open_drive(rig.link(timeout_s=0.3), 5)
            await d.connect()
            try:
                rig.fw.axes[0].jammed = True
                await d.exchange([10.0])
                await asyncio.sleep(0.3)
                await d.command(Command.CLEAR_FAULT)  # still jammed: no exception
                st = await eventually(d.read_state)
                assert st.axes[0].fault == Fault.STALL and st.axes[0].status & Status.FAULT
                rig.fw.axes[0].jammed = False
                await d.command(Command.CLEAR_FAULT)
                st = await eventually(d.read_state)
                assert not st.faulted
            finally:
                await d.close()

        run(scenario())
    finally:
        rig.close()


def test_lost_frames_are_counted_with_their_node():
    faults = CanFaults(frame_loss=1.0)
    assert faults.drop(can.Message(arbitration_id=0x185, data=b"\x00"))
    [event] = faults.drain()
    assert event.kind == "can_frame_lost" and event.device_id == 5
    faults = CanFaults()
    faults.state = "bus_off"
    assert faults.drop(can.Message(arbitration_id=0x705, data=b"\x05")) and not faults.drain()
    with pytest.raises(ValueError):
        CanFaults(frame_loss=2.0)


def test_a_link_keeps_only_its_recent_latencies():
    stats = LinkStats()
    policy = RetryPolicy(0, retry_on=(OSError,))

    async def ok():
        return 1

    async def many():
        for _ in range(LATENCY_WINDOW + 10):
            await policy.run(ok, what="x", label="y", stats=stats)

    run(many())
    assert stats.transactions == LATENCY_WINDOW + 10 and len(stats.latencies_s) == LATENCY_WINDOW


def test_a_state_stale_from_a_bus_fault_is_waited_for_not_failed(faulty_can):
    """The frames lost while the bus was off leave the cache stale (heartbeat and TPDOs
    older than three heartbeat periods); the first read after the bus is back waits for the
    next frames instead of failing the cycle (the soak lost setpoints to this)."""

    async def scenario():
        d = CanopenDrive(
            5,
            channel=faulty_can.channel,
            interface="virtual",
            timeout_s=0.3,
            producer_heartbeat_ms=500,
            stale_s=1.5,
        )
        await d.connect()
        try:
            await d.exchange([10.0])
            faulty_can.faults.state = "bus_off"
            await asyncio.sleep(2.0)  # > 3 heartbeat periods and > stale_s of silence
            faulty_can.faults.state = None
            st = await d.read_state()  # before: "heartbeat of node 5 lost" at once
            assert st.axes[0].target_deg == pytest.approx(10.0)
            faulty_can.faults.state = "bus_off"
            await asyncio.sleep(2.0)
            with pytest.raises(DriveCommError, match="heartbeat of node 5 lost|no TPDO"):
                await d.read_state()  # still off: refused after the wait
        finally:
            faulty_can.faults.state = None
            await d.close()

    run(scenario())
