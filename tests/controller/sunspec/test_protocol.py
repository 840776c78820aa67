"""Modbus protocol answers a SCADA integrator checks with a raw client: unserved function
codes, malformed requests, and how each refused write is logged."""

from __future__ import annotations

import logging
import socket
import struct
from contextlib import closing

import pytest
from pymodbus.client import ModbusTcpClient

from tests.controller.sunspec.test_server import HOST, Plant


def _exchange(sock: socket.socket, pdu: bytes, unit: int = 1, tid: int = 0x1234) -> bytes:
    """Send one Modbus TCP request; return the response PDU (after the MBAP header)."""
    sock.sendall(struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu)
    head = b""
    while len(head) < 7:
        chunk = sock.recv(7 - len(head))
        assert chunk, "server closed the connection"
        head += chunk
    rtid, pid, length, runit = struct.unpack(">HHHB", head)
    assert (rtid, pid, runit) == (tid, 0, unit)
    body = b""
    while len(body) < length - 1:
        chunk = sock.recv(length - 1 - len(body))
        assert chunk, "server closed the connection"
        body += chunk
    return body


@pytest.mark.parametrize(
    "pdu, answer",
    [
        (struct.pack(">BHH", 3, 40000, 126), bytes([0x83, 3])),  # quantity above 125
        (struct.pack(">BHH", 3, 40000, 0), bytes([0x83, 3])),  # quantity 0
        (struct.pack(">BHH", 4, 40000, 200), bytes([0x84, 3])),
        (struct.pack(">BHH", 0x41, 0, 1), bytes([0xC1, 1])),  # a function nobody defines
    ],
    ids=["fc3-126", "fc3-0", "fc4-200", "fc65"],
)
def test_a_malformed_request_is_answered_with_its_function_code(serve, pdu, answer):
    # Modbus application protocol 1.1b3, 6.3: a read quantity outside 1..125 is
    # exception 3 of that function; pymodbus answered function 0x80, exception 1, which
    # a SCADA cannot match to its request
    srv = serve(Plant(2))
    with closing(socket.create_connection((HOST, srv.port), timeout=2)) as s:
        assert _exchange(s, pdu) == answer
        # the connection still serves the next request
        ok = _exchange(s, struct.pack(">BHH", 3, 40000, 2))
        assert ok == bytes([3, 4]) + b"SunS"


@pytest.mark.parametrize("address", [40000, 0])
@pytest.mark.parametrize("writes_enabled", [False, True])
def test_coil_functions_are_answered_exception_1(serve, writes_enabled, address):
    # docs/sunspec.md: function codes other than 3, 4, 6, 16 get exception 1 (illegal
    # function), not exception 2 (the map has no coils: the function is not served)
    srv = serve(Plant(2), writes_enabled=writes_enabled)
    with closing(ModbusTcpClient(HOST, port=srv.port, timeout=2)) as c:
        assert c.connect()
        answers = [
            c.read_coils(address, count=8, device_id=1),
            c.read_discrete_inputs(address, count=8, device_id=1),
            c.write_coil(address, True, device_id=1),
            c.write_coils(address, [True, False], device_id=1),
        ]
    assert [(r.isError(), getattr(r, "exception_code", None)) for r in answers] == [(True, 1)] * 4
    assert srv.stats["writes_accepted"] == 0


def test_each_refused_write_is_logged_once_with_its_reason(serve, caplog):
    srv = serve(Plant(2), writes_enabled=True)
    caplog.set_level(logging.WARNING, logger="heliotrack.sunspec")
    with closing(ModbusTcpClient(HOST, port=srv.port, timeout=2)) as c:
        assert c.connect()
        da = srv.map.slot("DA", model=1).address
        r = c.write_register(da, 2, device_id=1)
    assert r.isError() and r.exception_code == 2
    lines = [rec.getMessage() for rec in caplog.records if rec.name == "heliotrack.sunspec"]
    assert len(lines) == 1, lines
    assert "DA is read-only" in lines[0]
    assert srv.stats["writes_refused"] == 1


def test_a_malformed_request_to_another_unit_is_answered_as_another_unit(serve):
    srv = serve(Plant(1))
    with closing(socket.create_connection((HOST, srv.port), timeout=2)) as s:
        assert _exchange(s, struct.pack(">BHH", 3, 40000, 126), unit=5) == bytes([0x83, 0x0B])
