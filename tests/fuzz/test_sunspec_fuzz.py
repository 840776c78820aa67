"""Fuzzing the SunSpec server's handling of writes from an allowed client (issue 13): any
function code, address, count and values give an answer (None or a Modbus exception code),
never an exception; an accepted write only ever carries angles inside the protocol range
and the tracker's limits, and valid Ctl and stow request values."""

from __future__ import annotations

import asyncio
import math
from datetime import datetime

import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from pymodbus.client import ModbusTcpClient

import controller.sunspec.server as server_module
from controller.sunspec import (
    OverrideCommand,
    PlantSnapshot,
    StowRequest,
    SunSpecServer,
    TrackerSnapshot,
    WeatherSnapshot,
)
from controller.sunspec.control import ControlTable, WriteRefused
from controller.sunspec.models import SUNSPEC_BASE_ADDRESS, SunSpecMap

from .strategies import bounded

EL_LIMITS, AZ_LIMITS = (5.0, 85.0), (-20.0, 380.0)
HOST = "127.0.0.1"


def plant(kind: str = "dual-axis", stow: str = "") -> PlantSnapshot:
    if kind == "single-axis":
        trackers = [
            TrackerSnapshot.row(f"r{i}", 10.0, 9.0, rotation_limits_deg=(-55.0, 55.0)) for i in range(3)
        ]
    else:
        trackers = [
            TrackerSnapshot(
                f"t{i}", 30.0, 170.0, 30.0, 170.0, el_limits_deg=EL_LIMITS, az_limits_deg=AZ_LIMITS
            )
            for i in range(3)
        ]
    return PlantSnapshot("fuzz", kind, datetime(2026, 6, 1, 12), trackers, weather=WeatherSnapshot(stow=stow))


MAP = SunSpecMap(3)
SPAN = (SUNSPEC_BASE_ADDRESS - 4, MAP.end_address + 4)
writable = [s for s in MAP.slots if s.point.writable]
words16 = st.integers(0, 0xFFFF)


@st.composite
def writes(draw) -> tuple[int, list[int]]:
    """Mostly near or on the writable points, sometimes anywhere."""
    if draw(st.booleans()):
        slot = draw(st.sampled_from(writable))
        address = slot.address + draw(st.integers(-2, 2))
        count = draw(st.integers(1, 8))
    else:
        address = draw(st.integers(0, 0xFFFF))
        count = draw(st.integers(1, 123))
    special = st.sampled_from([0, 1, 2, 3, 0x7FFF, 0x8000, 0xFFFF])
    return address, draw(st.lists(st.one_of(words16, special), min_size=count, max_size=count))


def check_commands(snapshot: PlantSnapshot, commands) -> None:
    for cmd in commands:
        if isinstance(cmd, StowRequest):
            assert cmd.kind in (None, "snow", "hail")
            continue
        assert isinstance(cmd, OverrideCommand) and cmd.ctl in ("Automatic", "Manual", "Calibrate")
        assert cmd.tracker is None or 0 <= cmd.tracker < len(snapshot.trackers)
        if cmd.el_deg is not None:
            lo, hi = (-55.0, 55.0) if snapshot.type == "single-axis" else EL_LIMITS
            assert math.isfinite(cmd.el_deg) and lo <= cmd.el_deg <= hi
        if cmd.az_deg is not None:
            assert snapshot.type == "dual-axis" and 0.0 <= cmd.az_deg < 360.0


@bounded(400)
@given(writes(), st.sampled_from(["dual-axis", "single-axis"]), st.sampled_from(["", "wind"]))
@example((MAP.slot("ElCtl", 0).address, [0x8000, 0x0000]), "dual-axis", "")  # int32 sentinel
@example((MAP.slot("Ctl", 2).address, [3]), "dual-axis", "")
def test_control_table_takes_any_write(write, kind, stow):
    address, words = write
    snap = plant(kind, stow)
    table = ControlTable(MAP)
    table.refresh(snap)
    try:
        commands = table.apply_write(snap, address, words, HOST)
    except WriteRefused as exc:
        assert int(exc.code) in (2, 3, 6)
        if int(exc.code) == 6:
            assert stow
        return
    check_commands(snap, commands)
    if stow:
        assert all(isinstance(c, StowRequest) for c in commands)


@pytest.fixture(scope="module")
def live_server():
    """A started server whose SimDevice action the tests call directly (fast, in-process),
    as the allowed client 127.0.0.1."""
    received: list = []
    srv = SunSpecServer(
        lambda: plant(), received.append, host=HOST, port=0, writes_enabled=True, allow=(HOST,)
    ).start()
    yield srv, received
    srv.stop()


@bounded(300)
@given(
    st.integers(0, 127),
    writes(),
    st.booleans(),
)
def test_the_server_answers_any_request(live_server, fc, write, is_write):
    srv, received = live_server
    address, words = write
    registers = [0] * 0x10000
    token = server_module._PEER.set(HOST)
    try:
        before = len(received)
        answer = asyncio.run(
            srv._action(fc, 0, address, len(words), registers, words if is_write else None)  # noqa: SLF001
        )
    finally:
        server_module._PEER.reset(token)
    assert answer is None or int(answer) in (1, 2, 3, 6)
    assert srv.stats["errors"] == 0  # no request ended in an exception
    check_commands(plant(), received[before:])


@bounded(25)
@given(st.sampled_from(writable), st.lists(words16, min_size=1, max_size=6), st.integers(-1, 1))
def test_over_tcp_any_write_is_answered_and_the_server_keeps_serving(live_server, slot, words, shift):
    srv, _ = live_server
    client = ModbusTcpClient(HOST, port=srv.port, timeout=2)
    assert client.connect()
    try:
        rr = client.write_registers(slot.address + shift, words, device_id=1)
        assert not rr.isError() or rr.exception_code in (2, 3, 6)
        rr = client.read_holding_registers(SUNSPEC_BASE_ADDRESS, count=2, device_id=1)
        assert rr.registers == [0x5375, 0x6E53]
    finally:
        client.close()
