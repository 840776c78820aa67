"""The emulated slcan (Lawicel) adapter: command replies, and python-can's slcan client
talking through the pty to a virtual bus."""

from __future__ import annotations

import can
import pytest

from hil.canopen.slcan import ERROR, OK, SlcanAdapter, open_slcan_pty
from hil.pty import PtyLink

from .rig import channel, wait_for


@pytest.fixture
def adapter():
    ch = channel()
    link, ad = open_slcan_pty(ch)
    try:
        yield ad, link, ch
    finally:
        ad.stop()
        ad.bus.shutdown()
        link.close()


def test_lawicel_command_replies():
    with PtyLink.open() as link:
        bus = can.Bus(interface="virtual", channel=channel())
        ad = SlcanAdapter(link, bus)  # not started: handle() only
        try:
            assert ad.handle("t1230") == ERROR  # channel closed
            assert ad.handle("S6") == OK
            assert ad.handle("S9") == ERROR
            assert ad.handle("O") == OK
            assert ad.handle("S6") == ERROR  # bit rate only while closed
            assert ad.handle("V") == b"V0110\r"
            assert ad.handle("N").startswith(b"N")
            assert ad.handle("F") == b"F00\r"
            assert ad.handle("t12321122") == b"z\r"
            assert ad.handle("T000001232AABB") == b"Z\r"
            assert ad.handle("t1232112") == ERROR  # data shorter than DLC
            assert ad.handle("t8001") == ERROR  # 11-bit id out of range, short
            assert ad.handle("t12391122334455667788") == ERROR  # DLC 9
            assert ad.handle("?") == ERROR
            assert ad.handle("C") == OK
            assert ad.bad_commands == 4
            msg = can.Message(arbitration_id=0x185, data=b"\x37\x02", is_extended_id=False)
            assert ad.encode(msg) == b"t18523702\r"
        finally:
            bus.shutdown()


def test_python_can_slcan_client_reaches_the_virtual_bus(adapter):
    ad, link, ch = adapter
    node_side = can.Bus(interface="virtual", channel=ch)
    client = can.Bus(interface="slcan", channel=link.path, sleep_after_open=0, bitrate=500000)
    try:
        client.send(can.Message(arbitration_id=0x605, data=b"\x40\x00\x10\x00", is_extended_id=False))
        got = node_side.recv(2)
        assert got is not None and got.arbitration_id == 0x605 and bytes(got.data) == b"\x40\x00\x10\x00"
        node_side.send(can.Message(arbitration_id=0x1ABCDE, data=b"\x01\x02", is_extended_id=True))
        back = None
        for _ in range(20):
            back = client.recv(0.1)
            if back is not None:
                break
        assert back is not None and back.is_extended_id
        assert back.arbitration_id == 0x1ABCDE and bytes(back.data) == b"\x01\x02"
        assert ad.bitrate_code == "6"
    finally:
        client.shutdown()
        node_side.shutdown()
    assert wait_for(lambda: not ad.is_open)  # the client's shutdown sent "C"


def test_a_second_open_drops_none_of_the_clients_frames(adapter):
    """python-can's client sends "O" after setting the bit rate and again at the end of its
    start: the adapter flushed the pty on that second "O", and a frame written for the
    client in between was lost under its reader ("device reports readiness to read but
    returned no data", its reception stopped for good).  Stale frames go at "C"."""
    import os
    import select
    import time

    ad, link, ch = adapter
    node_side = can.Bus(interface="virtual", channel=ch)
    fd = os.open(link.path, os.O_RDWR | os.O_NOCTTY)

    def drain(wait: float = 0.3) -> bytes:
        time.sleep(wait)  # the adapter answers from its own thread
        got = b""
        while select.select([fd], [], [], 0)[0]:
            got += os.read(fd, 256)
        return got

    try:
        os.write(fd, b"O\r")
        assert drain() == OK
        node_side.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
        assert wait_for(lambda: select.select([fd], [], [], 0)[0], 2.0)  # the frame is there
        os.write(fd, b"O\r")  # the second open
        assert drain() == b"t701105\r" + ERROR  # the frame kept, the second open refused
        node_side.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
        assert wait_for(lambda: select.select([fd], [], [], 0)[0], 2.0)
        os.write(fd, b"C\r")  # the client closes with a frame unread: dropped
        assert drain() == OK
        os.write(fd, b"O\r")
        assert drain() == OK
    finally:
        os.close(fd)
        node_side.shutdown()
