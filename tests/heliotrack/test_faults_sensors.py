"""Sensor faults from the emulated instruments, judged by the controller's readers before use:
an out-of-range, a "no value" (NaN) or a frozen pyranometer is never a sample (the frozen
one was, before: its register map has no sample counter)."""

import asyncio
import math

import pytest

from controller.drives import DriveCommError
from controller.drives.links import ModbusTcpLink
from controller.sensors.pyranometer import FROZEN_AFTER, ModbusPyranometer
from hil.modbus_server import ModbusServerThread
from hil.pyranometer import Pyranometer


def test_a_pyranometer_out_of_range_nan_or_frozen_gives_no_sample():
    t = [43200.0]
    pyr = Pyranometer(lambda _t: 600.0, lambda: t[0], noise_w_m2=2.0, seed=1)
    with ModbusServerThread({10: pyr}, tcp=("127.0.0.1", 0)) as srv:

        async def scenario():
            link = ModbusTcpLink(name="gw", host="127.0.0.1", tcp_port=srv.tcp_port, timeout_s=0.3, retries=0)
            reader = ModbusPyranometer.from_config(link, 10)
            try:
                for _ in range(2 * FROZEN_AFTER):  # a live instrument: never judged frozen
                    t[0] += 60.0
                    assert (await reader.read(t[0])).ghi_w_m2 == pytest.approx(600.0, abs=10)
                pyr.override = 2500.0
                with pytest.raises(DriveCommError, match="implausible"):
                    await reader.read(t[0])
                pyr.override = math.nan
                with pytest.raises(DriveCommError, match="implausible"):
                    await reader.read(t[0])
                pyr.override = None
                pyr.frozen_at = t[0]
                outcomes = []
                for _ in range(FROZEN_AFTER + 2):
                    t[0] += 60.0
                    try:
                        await reader.read(t[0])
                        outcomes.append("sample")
                    except DriveCommError as exc:
                        assert "frozen" in str(exc)
                        outcomes.append("frozen")
                assert outcomes[-3:] == ["frozen"] * 3
                pyr.frozen_at = None
                t[0] += 60.0
                assert (await reader.read(t[0])).ghi_w_m2 > 500  # back by itself
            finally:
                await reader.close()

        asyncio.run(scenario())


def test_a_dark_steady_reading_is_not_a_frozen_instrument():
    t = [0.0]
    pyr = Pyranometer(lambda _t: 0.0, lambda: t[0])
    with ModbusServerThread({10: pyr}, tcp=("127.0.0.1", 0)) as srv:

        async def scenario():
            link = ModbusTcpLink(name="gw", host="127.0.0.1", tcp_port=srv.tcp_port, timeout_s=0.3, retries=0)
            reader = ModbusPyranometer.from_config(link, 10)
            try:
                for _ in range(2 * FROZEN_AFTER):
                    t[0] += 60.0
                    assert (await reader.read(t[0])).ghi_w_m2 == 0.0  # night
            finally:
                await reader.close()

        asyncio.run(scenario())
